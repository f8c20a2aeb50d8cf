"""The one way a bench runs a launch file and collects its results: :func:`run_launch`.

    from roslaunch_run import run_launch

    run = run_launch({"rviz": False, "model": "models/reach", "task": "reach", "episodes": 20,
                      "seed": 700000}, port=11411, episodes=20)
    run.successes, run.episodes, run.failures   # from the simulator's outcome log
    run.records                                 # that log: one dict per episode
    run.wall_s, run.output                      # start to end of the run; roslaunch's printed lines

``roslaunch -p PORT fr5_rl sim_policy.launch ARG:=VALUE ... outcome_log:=FILE`` starts on its
own ROS master, headless. The simulator node (``~outcome_log``, config/sim_node.yaml) appends
each episode's outcome to FILE as one JSON line (src/fr5_rl/ros/sim_node.py
``finish_episode``)::

    {"episode": 1, "seed": 700000, "success": true, "failure": "", "steps": 57, "sim_time": 2.36}

(``late_periods`` too in lockstep). The run is over at the simulator node's last line (it
prints ``success rate: K/N`` once its last outcome is in FILE and it stops), when roslaunch says
a required node died or ends, or at the timeout; the launch is then stopped (SIGINT to its
process group, SIGKILL after 30 s). That line only marks the end (the node leaves the master
seconds later, and the benches' figures stop there); the outcomes are read from FILE, never
from the printed text. ``listen`` subscribes this process to the launch's topics for the run
(it joins the launch's master as a ROS node: one launch per process).

Imports only the standard library (and rospy to listen): no bench, no CLI.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, Iterable, List, Mapping, Optional

PACKAGE = "fr5_rl"
# A printed line holding one of these ends the run: the simulator's last line (all episodes
# done), roslaunch's word that a required node (simulator, camera, detector) died.
END_MARKERS = ("success rate:", "REQUIRED process")
OUTCOME_KEYS = ("episode", "seed", "success", "failure", "steps")  # what every outcome line carries
START_UP_S, PER_EPISODE_S = 180.0, 60.0  # default timeout: start-up plus this per episode
STOP_WAIT_S = 30.0  # after SIGINT, how long roslaunch may take to end before SIGKILL


# ----------------------------------------------------------------------------- outcomes
def parse_outcomes(text: str) -> List[Dict[str, Any]]:
    """The outcomes of an outcome log's text (one JSON object a line; blank lines skipped).

    :raises ValueError: a line that is not a JSON object with every key of ``OUTCOME_KEYS``."""
    records = []
    for number, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        try:
            record = json.loads(line)
        except ValueError as error:
            raise ValueError(f"outcome log line {number} is not JSON: {error}") from None
        missing = [key for key in OUTCOME_KEYS if not isinstance(record, dict) or key not in record]
        if missing:
            raise ValueError(f"outcome log line {number} lacks {', '.join(missing)}: {line.strip()[:200]}")
        records.append(record)
    return records


def read_outcomes(path: Path) -> List[Dict[str, Any]]:
    """:func:`parse_outcomes` of the file at ``path``; none when the file does not exist."""
    path = Path(path)
    return parse_outcomes(path.read_text(encoding="utf-8")) if path.exists() else []


def failures(records: Iterable[Mapping[str, Any]]) -> List[str]:
    """The failure cause of each failed episode, in episode order."""
    return [str(record["failure"]) for record in records if not record["success"]]


# ----------------------------------------------------------------------------- the command
def launch_value(value: Any) -> str:
    """A launch argument's value as roslaunch reads it: booleans ``true``/``false``, None ``""``."""
    if isinstance(value, bool):
        return "true" if value else "false"
    return "" if value is None else str(value)


def launch_command(arguments: Mapping[str, Any], port: int, launch_file: str = "sim_policy.launch",
                   package: str = PACKAGE) -> List[str]:
    """``roslaunch -p PORT PACKAGE LAUNCH_FILE NAME:=VALUE ...``, the arguments in their order."""
    return (["roslaunch", "-p", str(int(port)), package, launch_file]
            + [f"{name}:={launch_value(value)}" for name, value in arguments.items()])


def master_uri(port: int) -> str:
    return f"http://localhost:{int(port)}"


def default_timeout(episodes: int) -> float:
    """Seconds a launch of ``episodes`` episodes may take before it counts as hung."""
    return START_UP_S + PER_EPISODE_S * max(int(episodes), 1)


# ----------------------------------------------------------------------------- the run
@dataclass
class LaunchRun:
    """What one launch left: the outcomes (the simulator's outcome log), roslaunch's printed
    lines, the wall time from the start to the end of the run, roslaunch's exit status (None
    when it had to be stopped) and whether the timeout ended it."""

    command: List[str]
    records: List[Dict[str, Any]] = field(default_factory=list)
    output: List[str] = field(default_factory=list)
    wall_s: float = 0.0
    returncode: Optional[int] = None
    timed_out: bool = False

    @property
    def episodes(self) -> int:
        return len(self.records)

    @property
    def successes(self) -> int:
        return sum(bool(record["success"]) for record in self.records)

    @property
    def failures(self) -> List[str]:
        return failures(self.records)

    def lines_starting(self, prefix: str) -> List[str]:
        """The printed lines that start with ``prefix`` (stripped): what a node reports
        besides outcomes (the lockstep speed, the detector's warnings)."""
        return [line.strip() for line in self.output if line.startswith(prefix)]


def join_ros(node_name: str, timeout: float = 30.0, alive: Callable[[], bool] = lambda: True) -> bool:
    """Wait (up to ``timeout`` s, while ``alive()``) for the ROS master a bench's roslaunch is
    starting, then make this process a ROS node (anonymous, no signal handlers) unless it
    already is one. False, without joining, when no master answered (rospy would wait forever)."""
    import rospy

    deadline = time.time() + timeout
    while True:
        try:
            rospy.get_master().getPid()
            break
        except Exception:  # the master is not up yet (connection refused, timeouts)
            if time.time() >= deadline or not alive():
                return False
            time.sleep(0.5)
    if not rospy.core.is_initialized():
        rospy.init_node(node_name, anonymous=True, disable_signals=True)
    return True


def ends_run(line: str) -> bool:
    """Whether a line roslaunch printed marks the end of the run (:data:`END_MARKERS`)."""
    return any(marker in line for marker in END_MARKERS)


def _collect(stream: Iterable[str], lines: List[str], ended: List[float], end: threading.Event) -> None:
    """Keep every line roslaunch prints (read to the end: a full pipe would block it); at the
    first line that ends the run, note the time and set ``end``."""
    for line in stream:
        lines.append(line)
        if not end.is_set() and ends_run(line):
            ended.append(time.time())
            end.set()


def _default_sigint() -> None:
    """In the launch's process, before roslaunch starts: SIGINT does its default again. A bench run
    in the background (``nohup make bench &``, CI) inherits SIGINT ignored, and :func:`_stop`
    would then wait STOP_WAIT_S for every launch before killing it."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _stop(launch: subprocess.Popen) -> Optional[int]:
    """SIGINT to the launch's process group, SIGKILL if it has not ended within STOP_WAIT_S."""
    if launch.poll() is not None:
        return launch.returncode
    try:
        os.killpg(launch.pid, signal.SIGINT)
        launch.wait(timeout=STOP_WAIT_S)
    except subprocess.TimeoutExpired:
        os.killpg(launch.pid, signal.SIGKILL)
        launch.wait()
    except ProcessLookupError:
        launch.wait()
    return None


class SideLaunch:
    """A second launch on a running launch's master (e.g. record.launch beside the rehearsal),
    started by :meth:`start` and stopped (SIGINT, as Ctrl-C: rosbag closes its bag) by :meth:`stop`.

    :param launch_file: the launch file in this package; ``arguments`` its NAME:=VALUE pairs.
    """

    def __init__(self, launch_file: str, arguments: Mapping[str, Any], port: int) -> None:
        self.command = launch_command(arguments, port, launch_file)
        self.port = port
        self.process: Optional[subprocess.Popen] = None

    def start(self) -> "SideLaunch":
        env = dict(os.environ, ROS_MASTER_URI=master_uri(self.port))
        self.process = subprocess.Popen(self.command, stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT, env=env,
                                        start_new_session=True, preexec_fn=_default_sigint)
        return self

    def stop(self) -> Optional[int]:
        return _stop(self.process) if self.process is not None else None


def run_launch(arguments: Mapping[str, Any], *, port: int, episodes: int, launch_file: str = "sim_policy.launch",
               timeout: Optional[float] = None, listen: Optional[Callable[[], Iterable[Any]]] = None,
               node_name: str = "bench", poll_s: float = 0.1) -> LaunchRun:
    """Run ``roslaunch -p port fr5_rl launch_file`` with ``arguments`` (plus ``outcome_log``: a
    temporary file) until the run ends (:func:`ends_run`), roslaunch exits, or ``timeout`` s
    (default :func:`default_timeout` of ``episodes``) pass; stop it; collect the outcomes.

    ``listen``: called once this process has joined the launch's master as ROS node
    ``node_name``; it subscribes to what the bench measures and returns the subscribers, which
    are unregistered when the run is over (before the launch is stopped)."""
    if "outcome_log" in arguments:
        raise ValueError("run_launch sets outcome_log itself")
    uri = master_uri(port)
    env = dict(os.environ, ROS_MASTER_URI=uri)
    if listen is not None:
        os.environ["ROS_MASTER_URI"] = uri  # rospy reads it when this process joins
    deadline_s = default_timeout(episodes) if timeout is None else float(timeout)
    with tempfile.TemporaryDirectory(prefix="fr5_bench_") as scratch:
        log = Path(scratch) / "outcomes.jsonl"
        run = LaunchRun(launch_command({**arguments, "outcome_log": log}, port, launch_file))
        started = time.time()
        launch = subprocess.Popen(run.command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env,
                                  start_new_session=True, preexec_fn=_default_sigint)
        ended: List[float] = []
        end = threading.Event()
        reader = threading.Thread(target=_collect, args=(launch.stdout, run.output, ended, end), daemon=True)
        reader.start()
        subscribers: List[Any] = []
        try:
            if listen is not None and join_ros(node_name, deadline_s, alive=lambda: launch.poll() is None):
                subscribers = list(listen() or [])
            while not end.wait(poll_s) and launch.poll() is None:
                if time.time() - started > deadline_s:
                    run.timed_out = True
                    break
            if not end.is_set() and launch.poll() is not None:
                reader.join(timeout=5.0)  # it ended by itself: its last lines may hold the end
            run.wall_s = (ended[0] if ended else time.time()) - started
        finally:
            for subscriber in subscribers:
                subscriber.unregister()
            run.returncode = _stop(launch)
            reader.join(timeout=5.0)
        run.records = read_outcomes(log)
    if run.timed_out or run.episodes < episodes:
        why = (f"timed out after {deadline_s:.0f} s" if run.timed_out else
               "ended early" if run.returncode is None else f"roslaunch exited with {run.returncode}")
        tail = "".join(run.output[-30:])
        print(f"{launch_file}: {run.episodes}/{episodes} episodes, {why}; its last lines:\n{tail}",
              file=sys.stderr, flush=True)
    return run
