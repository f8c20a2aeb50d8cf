"""A node's share of the CPU: lower its scheduling priority so the control loop wins a busy machine."""
from __future__ import annotations

import os
from pathlib import Path
from typing import List


def _threads() -> List[int]:
    # Linux keeps a niceness and a scheduling policy per thread (nice(2) and
    # sched_setscheduler(2) change only the one named), so each thread in /proc/self/task is
    # set; elsewhere only the process is.
    tasks = Path("/proc/self/task")
    return [int(entry.name) for entry in tasks.iterdir()] if tasks.is_dir() else [0]


def lower_priority(nice: int, idle: bool = False) -> int:
    """Raise every thread of this process to niceness ``nice`` (0 = as started, 19 = lowest), so
    that on a loaded machine the scheduler runs the nodes at the default niceness first; on an
    idle one the process still gets all the CPU it wants. Threads started later inherit it.

    With ``idle``, every thread also goes to the ``SCHED_IDLE`` policy (Linux): it runs only on
    CPU time no normal thread wants, and a waking normal thread takes the core from it at once.
    A niceness only weighs the shares; on a machine with fewer cores than busy threads, a nice
    thread still holds a core for a slice while the control loop waits. Any user may choose it
    (it lowers the priority); where the platform has no ``SCHED_IDLE`` it is skipped.

    :param nice: target niceness, 0..19; a process already nicer is left as it is.
    :param idle: also move every thread to ``SCHED_IDLE``.
    :return: the niceness of the calling thread afterwards.
    :raises ValueError: ``nice`` outside 0..19.
    """
    if not 0 <= nice <= 19:
        raise ValueError(f"niceness must be 0..19 (19 lowest priority), got {nice}")
    idle_policy = getattr(os, "SCHED_IDLE", None) if idle else None
    for thread in _threads():
        try:
            if os.getpriority(os.PRIO_PROCESS, thread) < nice:
                os.setpriority(os.PRIO_PROCESS, thread, nice)
            if idle_policy is not None:
                os.sched_setscheduler(thread, idle_policy, os.sched_param(0))
        except (ProcessLookupError, PermissionError):
            pass  # a thread that ended meanwhile; lowering is always allowed, so no other case
    return os.getpriority(os.PRIO_PROCESS, 0)


def runs_idle() -> bool:
    """Whether the calling thread is under ``SCHED_IDLE`` (False where the platform has none)."""
    idle_policy = getattr(os, "SCHED_IDLE", None)
    return idle_policy is not None and os.sched_getscheduler(0) == idle_policy
