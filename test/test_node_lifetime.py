"""Every node of the package ends with its launch (issue #51): a launch ended as ``timeout -k``
ends it (SIGINT to its process group, SIGKILL 0.3 s later, before roslaunch has stopped its
nodes) leaves no node of the package running 3 s later. A real roslaunch, a real master."""
import os
import signal
import socket
import subprocess
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # a real launch: `make test`, not `make test-fast`


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def processes_logging_to(log_dir: Path) -> list:
    """Command lines of the processes roslaunch started with this log directory."""
    found = []
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            cmdline = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:
            continue
        if str(log_dir) in cmdline and "__name:=" in cmdline:
            found.append(cmdline)
    return found


def test_a_hard_killed_launch_leaves_no_node_of_the_package(tmp_path):
    port = free_port()
    env = dict(os.environ, ROS_MASTER_URI=f"http://127.0.0.1:{port}", ROS_LOG_DIR=str(tmp_path / "log"))
    launch = subprocess.Popen(["roslaunch", "-p", str(port), "fr5_rl", "sim_policy.launch", "rviz:=false"],
                              env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + 60
        nodes = []
        while time.monotonic() < deadline:  # up: the simulator and the policy node
            nodes = processes_logging_to(tmp_path / "log")
            if sum(("sim_node.py" in n) or ("policy_node.py" in n) for n in nodes) == 2:
                break
            time.sleep(0.5)
        assert sum(("sim_node.py" in n) or ("policy_node.py" in n) for n in nodes) == 2, nodes
        time.sleep(3.0)  # running: joint states, commands, episodes
        os.killpg(launch.pid, signal.SIGINT)  # as timeout -k does: the group, then SIGKILL
        time.sleep(0.3)
        os.killpg(launch.pid, signal.SIGKILL)
        launch.wait(10)
        deadline = time.monotonic() + 3.0
        while time.monotonic() < deadline and any("fr5_rl" in n for n in processes_logging_to(tmp_path / "log")):
            time.sleep(0.1)
        left = [n for n in processes_logging_to(tmp_path / "log") if "fr5_rl" in n]
        assert left == [], left
    finally:
        for cmdline in processes_logging_to(tmp_path / "log"):  # whatever is left (the master too)
            subprocess.run(["pkill", "-KILL", "-f", cmdline.split()[-1]], check=False)
        subprocess.run(["pkill", "-KILL", "-f", f"rosmaster --core -p {port}"], check=False)


def test_a_process_whose_parent_dies_is_told_and_a_stuck_one_is_ended(tmp_path):
    """The two mechanisms alone: PR_SET_PDEATHSIG, and the hard exit after the grace time."""
    marker, script = tmp_path / "ended", tmp_path / "child.py"
    script.write_text("import os, signal, time\n"
                      "from fr5_rl.ros.lifetime import die_with_parent\n"
                      f"signal.signal(signal.SIGTERM, lambda *_: (open({str(marker)!r}, 'w').close(), os._exit(0)))\n"
                      "assert die_with_parent()\n"
                      "time.sleep(30)\n")
    parent = subprocess.Popen(["bash", "-c", f"python3 {script} & wait"])
    time.sleep(1.5)
    parent.kill()  # the parent dies hard; the child hears of it
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline and not marker.exists():
        time.sleep(0.05)
    assert marker.exists()
    started = time.monotonic()
    stuck = subprocess.run(["python3", "-c", "import threading\n"
                            "from fr5_rl.ros.lifetime import exit_after\n"
                            "exit_after(0.5)\n"
                            "threading.Event().wait()\n"], timeout=10)
    assert stuck.returncode == 0 and time.monotonic() - started < 5
