"""tools/bench/benchlib.py and roslaunch_run.py, what the benchmarks share: percentiles, verdicts,
result files and summary.json; the one launch-and-collect helper (outcome logs, the roslaunch
command, the end of a run, with a stand-in roslaunch); the rules that only that helper starts
roslaunch and that nothing in tools/ imports a command-line module."""
import ast
import json
import os
import stat
import sys
import time
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parent.parent
TOOLS = REPO / "tools"
sys.path.insert(0, str(TOOLS / "bench"))

import benchlib  # noqa: E402
import roslaunch_run  # noqa: E402
from fr5_rl.deploy.bundle import machine_description  # noqa: E402


# ----------------------------------------------------------------------------- percentiles
def test_percentiles_of_known_data():
    values = list(range(1, 101))  # 1..100, numpy's linear interpolation
    assert benchlib.percentiles(values) == {"p50": pytest.approx(50.5), "p99": pytest.approx(99.01)}
    assert benchlib.percentiles([3.0, 1.0, 2.0], points=(0, 50, 100)) == {"p0": 1.0, "p50": 2.0, "p100": 3.0}
    assert benchlib.percentiles([]) == {"p50": None, "p99": None}


def test_latency_in_milliseconds_skips_non_finite_samples():
    seconds = [i / 1000.0 for i in range(1, 101)] + [float("nan"), float("inf")]
    stats = benchlib.latency_ms(seconds, points=(50, 90, 99), mean=True, digits=3)
    assert stats == {"p50_ms": 50.5, "p90_ms": 90.1, "p99_ms": 99.01, "mean_ms": 50.5, "max_ms": 100.0,
                     "samples": 100}
    assert benchlib.latency_ms([]) == {"p50_ms": None, "p99_ms": None, "max_ms": None, "samples": 0}


# ----------------------------------------------------------------------------- verdicts
@pytest.mark.parametrize("measured, target, comparison, met", [
    (0.05, 0.2, benchlib.AT_MOST, True),
    (0.2, 0.2, benchlib.AT_MOST, True),    # the target itself counts
    (0.25, 0.2, benchlib.AT_MOST, False),
    (153.0, 100.0, benchlib.AT_LEAST, True),
    (100.0, 100.0, benchlib.AT_LEAST, True),
    (74.6, 100.0, benchlib.AT_LEAST, False),
    (None, 100.0, benchlib.AT_LEAST, False),  # nothing measured is never met
    (None, 3.0, benchlib.AT_MOST, False),
])
def test_verdict_both_ways(measured, target, comparison, met):
    result = benchlib.verdict(measured, target, comparison, "ms", "latency p99")
    assert result["met"] is met
    assert result["verdict"] == ("met" if met else "not met")
    assert result["comparison"] == comparison and result["target"] == target
    assert result["text"].startswith("latency p99 ") and result["text"].endswith(": met" if met else ": not met")
    if measured is not None:
        assert ("<=" if comparison == benchlib.AT_MOST else ">=") in result["text"]
    assert benchlib.pass_fail(result) == ("PASS" if met else "FAIL")


def test_verdict_refuses_an_unknown_comparison():
    with pytest.raises(ValueError):
        benchlib.verdict(1.0, 2.0, "below")


# ----------------------------------------------------------------------------- result files
def test_written_result_has_the_machine_and_no_absolute_repository_path(tmp_path):
    verdicts = {"p99_ms": benchlib.verdict(0.1, 0.2, benchlib.AT_MOST, "ms")}
    data = {"model_dir": REPO / "models" / "reach", "reason": f"{REPO / 'models' / 'none'} does not exist",
            "nested": [{"path": str(REPO / "bench" / "results")}], "value": np.float64(1.5),
            "outside": Path("/opt/elsewhere/model")}
    path = benchlib.write_result(tmp_path / "bench_x.json", data, verdicts, machine={"load": 0.5})
    text = path.read_text()
    assert str(REPO) not in text
    assert "/opt/elsewhere" not in text
    result = json.loads(text)
    for key, value in machine_description().items():
        assert result["machine"][key] == value
    assert result["machine"]["load"] == 0.5
    assert result["model_dir"] == "models/reach"
    assert result["reason"] == "models/none does not exist"
    assert result["nested"][0]["path"] == "bench/results"
    assert result["outside"] == ".../model"
    assert result["value"] == 1.5
    assert result["generated"] and result["verdicts"]["p99_ms"]["met"] is True


def test_relative_path():
    assert benchlib.relative_path(REPO / "docs" / "bench") == "docs/bench"
    assert benchlib.relative_path(REPO) == "."
    assert benchlib.relative_path("models/reach") == "models/reach"
    assert benchlib.relative_path(Path("/somewhere/else/run")) == ".../run"
    assert benchlib.RESULTS_DIR == REPO / "bench" / "results"
    assert benchlib.DOCS_BENCH_DIR == REPO / "docs" / "bench"


# ----------------------------------------------------------------------------- summary.json
def _write(results, name, met):
    verdicts = {"target": benchlib.verdict(1.0 if met else 3.0, 2.0, benchlib.AT_MOST, "ms", name)}
    return benchlib.write_result(results / f"{name}.json", {"quick": True}, verdicts)


def test_summary_update_keeps_the_other_benches(tmp_path):
    (tmp_path / "summary.json").write_text(json.dumps({"verdicts": {"old.format": "PASS"}, "results": {}}))
    benchlib.update_summary(tmp_path, "bench_a", _write(tmp_path, "bench_a", met=True))
    benchlib.update_summary(tmp_path, "bench_b", _write(tmp_path, "bench_b", met=True))
    summary = benchlib.update_summary(tmp_path, "bench_a", _write(tmp_path, "bench_a", met=False))
    data = json.loads(summary.read_text())
    assert set(data["benches"]) == {"bench_a", "bench_b"}
    assert data["benches"]["bench_a"]["verdicts"]["target"]["met"] is False  # replaced
    assert data["benches"]["bench_b"]["verdicts"]["target"]["met"] is True   # kept
    assert data["benches"]["bench_b"]["file"] == "bench_b.json"
    assert set(data["verdicts"]) == {"bench_a.target", "bench_b.target"}
    assert data["verdicts"]["bench_a.target"].endswith("not met")
    assert (data["targets_met"], data["targets_not_met"]) == (1, 1)


def test_summary_rebuilt_from_the_result_files(tmp_path):
    _write(tmp_path, "bench_a", met=True)
    _write(tmp_path, "bench_b", met=False)
    (tmp_path / "no_verdicts.json").write_text("{}")
    data = json.loads(benchlib.rebuild_summary(tmp_path).read_text())
    assert set(data["benches"]) == {"bench_a", "bench_b"}
    assert (data["targets_met"], data["targets_not_met"]) == (1, 1)


def test_published_summary_carries_every_bench():
    """docs/bench/summary.json: a verdict for every result file published beside it (env
    speed, inference, the ROS loops, time to solve), each the same as in its file."""
    docs = benchlib.DOCS_BENCH_DIR
    summary = json.loads((docs / "summary.json").read_text())
    results = sorted(p.stem for p in docs.glob("*.json") if p.name != "summary.json")
    assert {"env_speed", "inference", "ros_loop_reach", "time_to_solve_reach"} <= set(results)
    assert sorted(summary["benches"]) == results
    for name in results:
        verdicts = json.loads((docs / f"{name}.json").read_text())["verdicts"]
        assert verdicts, f"{name}.json has no verdicts"
        assert summary["benches"][name]["verdicts"] == verdicts, f"summary.json is stale for {name}"


# ----------------------------------------------------------------------------- imports of tools/
FORBIDDEN_MODULES = ("fr5_rl.cli", "fr5_rl.policy", "fr5_rl.training.artifacts", "fr5_rl.training.evaluate",
                     "fr5_rl.training.export_onnx")
# Command-line paths of library modules (they take an argparse.Namespace).
FORBIDDEN_NAMES = {"fr5_rl.training.train": {"train"}, "fr5_rl.training.imitation": {"run_dagger"}}


def forbidden_imports(source: str):
    """The imports in ``source`` of a command-line module or a removed module."""
    found = []

    def check(module: str, line: int) -> None:
        if any(module == bad or module.startswith(bad + ".") for bad in FORBIDDEN_MODULES):
            found.append((line, module))

    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            for alias in node.names:
                check(alias.name, node.lineno)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            for alias in node.names:  # also catches `from fr5_rl.training import evaluate`
                check(f"{node.module}.{alias.name}", node.lineno)
                if alias.name in FORBIDDEN_NAMES.get(node.module, ()):
                    found.append((node.lineno, f"{node.module}.{alias.name}"))
    return found


def test_the_import_check_finds_forbidden_imports():
    bad = ("import fr5_rl.cli.evaluate\nfrom fr5_rl.cli import train\nfrom fr5_rl import cli\n"
           "from fr5_rl.training import evaluate, export_onnx\nfrom fr5_rl.policy import load_policy\n"
           "from fr5_rl.training.artifacts import META_FILE\nfrom fr5_rl.training.train import train\n"
           "def f():\n    from fr5_rl.training.imitation import run_dagger\n")
    assert [line for line, _ in forbidden_imports(bad)] == [1, 2, 3, 4, 4, 5, 6, 7, 9]
    good = ("from fr5_rl.training.evaluation import run_episodes\nfrom fr5_rl.training.onnx_export import export\n"
            "from fr5_rl.deploy.policy import load_policy\nfrom fr5_rl.training.train import make_vec_env\n")
    assert forbidden_imports(good) == []


def test_no_tool_imports_a_command_line_or_removed_module():
    tools = sorted(TOOLS.glob("*.py")) + sorted((TOOLS / "bench").glob("*.py"))
    assert {"env_and_inference.py", "ros_loop.py", "time_to_solve.py", "benchlib.py", "roslaunch_run.py",
            "ship_model.py"} <= {p.name for p in tools}
    offences = {p.name: forbidden_imports(p.read_text(encoding="utf-8")) for p in tools}
    assert {name: found for name, found in offences.items() if found} == {}



# ----------------------------------------------------------------------------- roslaunch_run
# Two lines as src/fr5_rl/ros/sim_node.py's _finish_episode writes them (lockstep adds late_periods).
OUTCOME_LOG = ('{"episode": 1, "seed": 700000, "success": true, "failure": "", "steps": 57, "sim_time": 2.36}\n'
               '\n'
               '{"episode": 2, "seed": 700001, "success": false, "failure": "knocked_over", "steps": 120, '
               '"sim_time": 5.8, "late_periods": 1}\n')


def test_outcome_log_parsed_and_counted():
    records = roslaunch_run.parse_outcomes(OUTCOME_LOG)
    assert [r["seed"] for r in records] == [700000, 700001]
    assert records[1]["late_periods"] == 1
    run = roslaunch_run.LaunchRun(command=[], records=records)
    assert (run.successes, run.episodes, run.failures) == (1, 2, ["knocked_over"])
    assert roslaunch_run.LaunchRun(command=[]).episodes == 0


@pytest.mark.parametrize("text", ["not json\n", '["a list"]\n', '{"episode": 1, "seed": 3, "success": true}\n'])
def test_outcome_log_refuses_what_the_simulator_does_not_write(text):
    with pytest.raises(ValueError, match="line 1"):
        roslaunch_run.parse_outcomes(text)


def test_outcome_log_read_from_file(tmp_path):
    assert roslaunch_run.read_outcomes(tmp_path / "missing.jsonl") == []
    (tmp_path / "log.jsonl").write_text(OUTCOME_LOG)
    assert len(roslaunch_run.read_outcomes(tmp_path / "log.jsonl")) == 2


def test_launch_command_spells_the_arguments_as_roslaunch_reads_them():
    command = roslaunch_run.launch_command({"rviz": False, "lockstep": True, "model": "models/reach", "episodes": 20,
                                            "camera_rate": None, "outcome_log": Path("/tmp/x.jsonl")}, 11411)
    assert command == ["roslaunch", "-p", "11411", "fr5_rl", "sim_policy.launch", "rviz:=false", "lockstep:=true",
                       "model:=models/reach", "episodes:=20", "camera_rate:=", "outcome_log:=/tmp/x.jsonl"]
    assert roslaunch_run.master_uri(11411) == "http://localhost:11411"
    assert roslaunch_run.default_timeout(20) > roslaunch_run.default_timeout(2) > 0


def test_end_of_run_lines():
    assert roslaunch_run.ends_run("success rate: 19/20\n")
    assert roslaunch_run.ends_run("REQUIRED process [camera-3] has died!\n")
    assert not roslaunch_run.ends_run("[INFO] [/fr5_sim]: episode 3 (seed 700002): success after 40 steps\n")
    assert not roslaunch_run.ends_run("lockstep: 12.0 s simulated in 4.1 s of wall time (2.9x real time)\n")


def test_sim_policy_launch_passes_outcome_log_to_the_simulator():
    """The helper sets ``outcome_log:=FILE``: the launch file must take it and hand it to the sim node."""
    launch = (REPO / "launch" / "sim_policy.launch").read_text(encoding="utf-8")
    assert '<arg name="outcome_log"' in launch
    assert '<param name="outcome_log" value="$(arg outcome_log)"/>' in launch
    assert "outcome_log:" in (REPO / "config" / "sim_node.yaml").read_text(encoding="utf-8")


FAKE_ROSLAUNCH = """#!/bin/sh
# Stand-in for roslaunch: writes two outcomes to the outcome_log argument, prints the simulator's
# last line (unless FAKE_SILENT is set), then runs until it is stopped; FAKE_FAIL: fails at once.
for arg in "$@"; do case "$arg" in outcome_log:=*) log="${arg#outcome_log:=}";; esac; done
echo "started $*"
[ -z "$FAKE_FAIL" ] || { echo "RLException: multiple files named [sim_policy.launch]"; exit 1; }
printf '%s\\n' '{"episode": 1, "seed": 5, "success": true, "failure": "", "steps": 9, "sim_time": 1.0}' >> "$log"
printf '%s\\n' '{"episode": 2, "seed": 6, "success": false, "failure": "timeout", "steps": 50, "sim_time": 2.0}' >> "$log"
[ -n "$FAKE_SILENT" ] || echo "success rate: 1/2"
exec sleep 60
"""


@pytest.fixture
def fake_roslaunch(tmp_path, monkeypatch):
    script = tmp_path / "bin" / "roslaunch"
    script.parent.mkdir()
    script.write_text(FAKE_ROSLAUNCH)
    script.chmod(script.stat().st_mode | stat.S_IXUSR)
    monkeypatch.setenv("PATH", f"{script.parent}{os.pathsep}{os.environ['PATH']}")
    return script


def test_run_launch_collects_the_outcome_log_and_stops_the_launch(fake_roslaunch):
    started = time.time()
    run = roslaunch_run.run_launch({"rviz": False, "episodes": 2, "seed": 5}, port=11499, episodes=2, timeout=30)
    assert time.time() - started < 20  # stopped at the end line, not at the timeout
    assert [r["seed"] for r in run.records] == [5, 6]
    assert (run.successes, run.episodes, run.failures) == (1, 2, ["timeout"])
    assert not run.timed_out and run.returncode is None  # it had to be stopped
    assert run.command[:5] == ["roslaunch", "-p", "11499", "fr5_rl", "sim_policy.launch"]
    assert run.command[-1].startswith("outcome_log:=")
    assert run.lines_starting("started") and 0 < run.wall_s < 20
    with pytest.raises(ValueError):
        roslaunch_run.run_launch({"outcome_log": "x"}, port=11499, episodes=1)


def test_run_launch_times_out(fake_roslaunch, monkeypatch):
    monkeypatch.setenv("FAKE_SILENT", "1")
    run = roslaunch_run.run_launch({}, port=11499, episodes=2, timeout=1.0)
    assert run.timed_out and 1.0 <= run.wall_s < 10
    assert run.episodes == 2  # what the log holds is kept


def test_run_launch_that_fails_at_once_neither_hangs_nor_listens(fake_roslaunch, monkeypatch):
    """A bench that listens must not wait forever for a master that roslaunch never started."""
    pytest.importorskip("rospy")
    monkeypatch.setenv("FAKE_FAIL", "1")
    monkeypatch.setenv("ROS_MASTER_URI", "http://localhost:11499")  # run_launch sets it: restored after
    listened = []
    started = time.time()
    run = roslaunch_run.run_launch({}, port=11499, episodes=2, timeout=60, listen=lambda: listened.append(1) or [])
    assert time.time() - started < 20 and not run.timed_out
    assert listened == [] and run.records == [] and run.returncode == 1
    assert run.lines_starting("RLException")


def _string_constants(path: Path):
    return [node.value for node in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
            if isinstance(node, ast.Constant) and isinstance(node.value, str)]


def offending_launch_code(path: Path):
    """Strings in a bench that would start roslaunch or read outcomes from its printed text."""
    return [text for text in _string_constants(path)
            if text == "roslaunch" or "success rate:" in text or "failure \\(" in text]


def test_only_the_helper_starts_roslaunch_or_reads_its_printed_outcomes(tmp_path):
    benches = sorted((TOOLS / "bench").glob("*.py"))
    assert {"ros_loop.py", "lockstep.py", "vision.py"} <= {p.name for p in benches}
    offences = {p.name: offending_launch_code(p) for p in benches if p.name != "roslaunch_run.py"}
    assert {name: found for name, found in offences.items() if found} == {}
    own = tmp_path / "own_launch.py"  # the check finds a bench with its own launch code
    own.write_text('import re, subprocess\nsubprocess.Popen(["roslaunch", "-p", "1", "fr5_rl", "x.launch"])\n'
                   're.search(r"success rate: (\\d+)/(\\d+)", "")\nre.findall(r"failure \\(([^)]*)\\)", "")\n')
    assert set(offending_launch_code(own)) == {"roslaunch", "success rate: (\\d+)/(\\d+)", "failure \\(([^)]*)\\)"}


# ----------------------------------------------------------------------------- every tool starts
TOOL_SCRIPTS = sorted([*TOOLS.glob("*.py"), *(TOOLS / "bench").glob("*.py")])


@pytest.mark.integration  # command lines in new interpreters: `make lint`
@pytest.mark.parametrize("script", [path for path in TOOL_SCRIPTS if "argparse" in path.read_text(encoding="utf-8")],
                         ids=lambda path: str(path.relative_to(TOOLS)))
def test_every_tool_with_a_command_line_starts(script):
    """A moved module breaks a tool's imports, and nothing else runs it before a user does
    (ship_model.py still imported benchlib from its old place)."""
    import subprocess

    result = subprocess.run([sys.executable, str(script), "--help"], capture_output=True, text=True, timeout=120,
                            cwd=str(REPO))
    assert result.returncode == 0, result.stderr[-2000:]
    assert "usage" in result.stdout.lower()


@pytest.mark.integration  # command lines in new interpreters: `make lint`
# ----------------------------------------------------------------------------- the release to compare against
def test_reference_tree_runs_that_commit_s_code_not_this_checkout(tmp_path, monkeypatch):
    """The old-against-new benches (issue #30) run a commit's export; a child given
    reference_environment imports fr5_rl and finds its config there, not here."""
    import subprocess

    import reference

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    tree = reference.reference_tree("HEAD")
    assert tree.parent == tmp_path / "fr5_rl" / "reference"
    assert (tree / "package.xml").is_file() and (tree / "src" / "fr5_rl" / "envs.py").is_file()
    assert reference.reference_tree("HEAD") == tree  # exported once, reused
    probe = "import fr5_rl, fr5_rl.config as c; print(fr5_rl.__file__); print(c.package_root())"
    shown = subprocess.run([sys.executable, "-c", probe], env=reference.reference_environment(tree),
                           capture_output=True, text=True, check=True).stdout.split()
    assert Path(shown[0]).resolve().is_relative_to(tree.resolve())
    assert Path(shown[1]).resolve() == tree.resolve()
    assert str(REPO / "src") not in reference.reference_environment(tree)["PYTHONPATH"].split(os.pathsep)


def test_old_and_new_alternate_and_so_does_which_goes_first():
    import reference

    orders = [reference.alternating(index) for index in range(4)]
    assert orders == [("new", "old"), ("old", "new"), ("new", "old"), ("old", "new")]


def test_an_unknown_release_says_what_to_do(tmp_path, monkeypatch):
    import reference

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    with pytest.raises(reference.ReferenceUnavailable, match="--reference"):
        reference.reference_tree("0" * 40)
    assert len(reference.reference_release()) >= 7  # the file names a commit


# ----------------------------------------------------------------------------- the rehearsal's timing
def test_rehearsal_timing_summary_reads_the_nodes_fields():
    import rehearsal

    # The policy node's ~timing: period, inference, compute latency, joint state age, wait, repeated (s),
    # each kept with the monotonic time it arrived; the camera's: render, convert, publish, age.
    policy = [(float(k), 0.02, 0.001 * k, 0.002 * k, 0.003 * k, 0.0, 0.0) for k in range(1, 101)]
    camera = [(0.1 * k, 0.03, 0.002, 0.001, 0.05 + 0.001 * k) for k in range(31)]  # 30 frames in 3 s
    summary = rehearsal.timing_summary({"policy": policy, "camera": camera})
    assert summary["inference"]["p50_ms"] == pytest.approx(50.5)
    assert summary["compute_latency"]["max_ms"] == pytest.approx(200.0)
    assert summary["joint_state_age"]["p99_ms"] == pytest.approx(297.03)
    assert summary["camera_frames_per_s"] == pytest.approx(10.0)
    assert summary["camera_frame_age"]["max_ms"] == pytest.approx(80.0)
    without_camera = rehearsal.timing_summary({"policy": policy})
    assert "camera_frames_per_s" not in without_camera and without_camera["compute_latency"]["samples"] == 100
