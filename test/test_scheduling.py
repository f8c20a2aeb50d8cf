"""fr5_rl.ros.scheduling: a node's niceness (and SCHED_IDLE) reaches every thread it has and will have."""
import os
import subprocess
import sys
import textwrap

import pytest

from fr5_rl.ros.scheduling import lower_priority

CHILD = textwrap.dedent("""
    import os, threading, time
    from fr5_rl.ros.scheduling import lower_priority

    def niceness():
        return os.getpriority(os.PRIO_PROCESS, threading.get_native_id())

    stop = threading.Event()
    seen = {}
    def before():
        stop.wait()
        seen["before"] = niceness()
    early = threading.Thread(target=before)
    early.start()
    time.sleep(0.05)
    print(lower_priority(int(os.environ["NICE"])))
    late = threading.Thread(target=lambda: seen.__setitem__("after", niceness()))
    late.start(); late.join()
    stop.set(); early.join()
    print(seen["before"], seen["after"], niceness())
    print(lower_priority(int(os.environ["AGAIN"])))
""")


def run_child(nice: int, again: int) -> list:
    result = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True, check=True,
                            env={**os.environ, "NICE": str(nice), "AGAIN": str(again)})
    return [line.split() for line in result.stdout.split("\n") if line]


def test_every_thread_before_and_after_takes_the_niceness():
    lines = run_child(7, 3)
    assert lines[0] == ["7"]
    assert lines[1] == ["7", "7", "7"]  # a thread started before, one started after, the caller
    assert lines[2] == ["7"]  # asking for less niceness later never raises the priority again


@pytest.mark.parametrize("nice", [-1, 20])
def test_niceness_outside_0_to_19_is_refused(nice):
    with pytest.raises(ValueError, match="0..19"):
        lower_priority(nice)


IDLE_CHILD = textwrap.dedent("""
    import os, threading
    from fr5_rl.ros.scheduling import lower_priority, runs_idle

    def policy():
        return os.sched_getscheduler(threading.get_native_id())

    stop = threading.Event()
    seen = {}
    early = threading.Thread(target=lambda: (stop.wait(), seen.__setitem__("before", policy())))
    early.start()
    print(runs_idle(), lower_priority(5, idle=True), runs_idle())
    late = threading.Thread(target=lambda: seen.__setitem__("after", policy()))
    late.start(); late.join()
    stop.set(); early.join()
    print(seen["before"] == os.SCHED_IDLE, seen["after"] == os.SCHED_IDLE, policy() == os.SCHED_IDLE)
""")


@pytest.mark.skipif(not hasattr(os, "SCHED_IDLE"), reason="SCHED_IDLE is Linux's")
def test_idle_moves_every_thread_before_and_after_to_sched_idle():
    result = subprocess.run([sys.executable, "-c", IDLE_CHILD], capture_output=True, text=True, check=True)
    lines = [line.split() for line in result.stdout.split("\n") if line]
    assert lines[0] == ["False", "5", "True"]  # normal before; niced and idle after
    assert lines[1] == ["True", "True", "True"]  # a thread started before, one started after, the caller
