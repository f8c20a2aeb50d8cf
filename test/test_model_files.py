"""Every broken or mismatched model file is refused with one clear line that names the file,
says what is wrong and what to do: by the loader (ModelFilesError), by the command-line tools
(exit status 2, no traceback) and by the policy node (fatal log, non-zero exit)."""
import json
import os
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from fr5_rl.deploy.bundle import ModelFilesError
from fr5_rl.deploy.policy import load_policy

ROOT = Path(__file__).resolve().parent.parent
REACH, GRASP = ROOT / "models" / "reach", ROOT / "models" / "grasp"


def copy_model(tmp_path: Path, source: Path = REACH) -> Path:
    target = tmp_path / "model"
    shutil.copytree(source, target)
    return target


def truncate(path: Path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 3])


def garbage(path: Path) -> None:
    path.write_bytes(b"garbage\n" * 64)


def edit_meta(model: Path, change) -> None:
    meta = json.loads((model / "meta.json").read_text())
    change(meta)
    (model / "meta.json").write_text(json.dumps(meta))


# Each case: (name, how to break a copy of models/reach, backend, file the message must name, words it must hold)
CASES = [
    ("model.zip truncated", lambda m: truncate(m / "model.zip"), "torch", "model.zip", "not a zip archive"),
    ("model.zip garbage", lambda m: garbage(m / "model.zip"), "torch", "model.zip", "not a zip archive"),
    ("model.zip missing", lambda m: (m / "model.zip").unlink(), "torch", "model.zip", "missing"),
    ("vecnormalize.pkl truncated", lambda m: truncate(m / "vecnormalize.pkl"), "torch", "vecnormalize.pkl", "could not be loaded"),
    ("vecnormalize.pkl garbage", lambda m: garbage(m / "vecnormalize.pkl"), "torch", "vecnormalize.pkl", "could not be loaded"),
    ("vecnormalize.pkl missing", lambda m: (m / "vecnormalize.pkl").unlink(), "torch", "vecnormalize.pkl", "normalisation statistics"),
    ("vecnormalize.pkl of another model", lambda m: shutil.copy(GRASP / "vecnormalize.pkl", m), "torch", "vecnormalize.pkl", "different models"),
    ("model.zip of another model", lambda m: shutil.copy(GRASP / "model.zip", m), "torch", "model.zip", "different models"),
    ("model.onnx truncated", lambda m: truncate(m / "model.onnx"), "onnx", "model.onnx", "could not be loaded"),
    ("model.onnx garbage", lambda m: garbage(m / "model.onnx"), "onnx", "model.onnx", "could not be loaded"),
    ("model.onnx missing", lambda m: (m / "model.onnx").unlink(), "onnx", "model.onnx", "export_onnx.py"),
    ("model.onnx of another model", lambda m: shutil.copy(GRASP / "model.onnx", m), "onnx", "model.onnx", "re-export"),
    ("meta.json missing", lambda m: (m / "meta.json").unlink(), "onnx", "meta.json", "missing"),
    ("meta.json invalid JSON", lambda m: (m / "meta.json").write_text('{"task": "reach",'), "onnx", "meta.json", "not valid JSON"),
    ("meta.json not an object", lambda m: (m / "meta.json").write_text("[1, 2]"), "onnx", "meta.json", "JSON object"),
    ("meta.json binary", lambda m: (m / "meta.json").write_bytes(b"\xff\xfe\x00"), "onnx", "meta.json", "damaged"),
    ("meta.json lacks task", lambda m: edit_meta(m, lambda d: d.pop("task")), "onnx", "meta.json", "lacks 'task'"),
    ("meta.json lacks observation_size", lambda m: edit_meta(m, lambda d: d.pop("observation_size")), "torch", "meta.json", "lacks 'observation_size'"),
    ("meta.json size of wrong type", lambda m: edit_meta(m, lambda d: d.update(action_size="7")), "onnx", "meta.json", "must be a int"),
    ("observation size of another version", lambda m: edit_meta(m, lambda d: d.update(observation_size=25)), "onnx", "meta.json", "retrain"),
    ("action size of another version", lambda m: edit_meta(m, lambda d: d.update(action_size=8)), "torch", "meta.json", "retrain"),
    ("unknown task", lambda m: edit_meta(m, lambda d: d.update(task="stack")), "onnx", "meta.json", "unknown task"),
    ("unknown algorithm", lambda m: edit_meta(m, lambda d: d.update(algo="dqn")), "torch", "meta.json", "unknown algorithm"),
    ("says it observes previous actions its files lack", lambda m: edit_meta(m, lambda d: d["env_overrides"].update(observation={"previous_actions": 2})), "onnx", "meta.json", "retrain"),
    ("trained with another action scaling", lambda m: edit_meta(m, lambda d: d["env_config"]["action"].update(max_joint_step=0.02)), "onnx", "", "retrain"),
    # Trained with tcp-space actions, its overrides lost: loaded, it would run in joint space.
    ("trained in tcp space, run in joint space", lambda m: edit_meta(m, lambda d: d["env_config"]["action"].update(
        space="tcp", max_tcp_translation_step=0.02, max_tcp_rotation_step=0.04)), "torch", "", "action"),
]


@pytest.mark.parametrize("name, damage, backend, file, words", CASES, ids=[c[0] for c in CASES])
def test_loader_names_the_file_and_the_remedy(tmp_path, name, damage, backend, file, words):
    model = copy_model(tmp_path)
    damage(model)
    with pytest.raises(ModelFilesError) as caught:
        load_policy(model, backend)
    message = str(caught.value)
    assert "\n" not in message, message
    assert words in message, message
    assert str(model / file) in message or (not file and str(model) in message), message


def test_intact_copy_loads_with_both_backends(tmp_path):
    """The damage above is what fails: the undamaged copy loads and acts."""
    model = copy_model(tmp_path)
    for backend in ("torch", "onnx"):
        policy = load_policy(model, backend)
        action = policy.act(np.zeros(policy.observation_size, dtype=np.float32))
        assert action.shape == (7,)


def test_a_model_saved_before_action_space_existed_loads_in_joint_space(tmp_path):
    """models/reach's meta.json records the action section without ``space`` (it predates it):
    it loads, and its deployment shapes joint increments; told it was tcp space, it refuses."""
    model = copy_model(tmp_path)
    assert "space" not in json.loads((model / "meta.json").read_text())["env_config"]["action"]
    assert load_policy(model, "onnx").meta["task"] == "reach"
    edit_meta(model, lambda d: d["env_config"]["action"].update(space="tcp"))
    with pytest.raises(ModelFilesError, match="action"):
        load_policy(model, "onnx")


def run_script(script: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(ROOT / "scripts" / script), *args], capture_output=True, text=True,
                          stdin=subprocess.DEVNULL, timeout=180, cwd=ROOT)


@pytest.mark.slow  # each runs a command line in a new interpreter
@pytest.mark.parametrize("script, damage, file", [
    ("evaluate.py", lambda m: truncate(m / "model.zip"), "model.zip"),
    ("evaluate.py", lambda m: garbage(m / "vecnormalize.pkl"), "vecnormalize.pkl"),
    ("export_onnx.py", lambda m: (m / "meta.json").write_text("{"), "meta.json"),
    ("export_onnx.py", lambda m: edit_meta(m, lambda d: d.update(observation_size=30)), "meta.json"),
], ids=["evaluate-zip", "evaluate-pkl", "export-meta", "export-size"])
def test_command_line_tools_print_one_line_and_exit_2(tmp_path, script, damage, file):
    model = copy_model(tmp_path)
    damage(model)
    result = run_script(script, str(model), "--episodes", "1") if script == "evaluate.py" else run_script(script, str(model))
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr, result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith(f"{script}: ") and str(model / file) in lines[0], result.stderr


def test_evaluate_onnx_backend_of_a_damaged_onnx_exits_2(tmp_path):
    model = copy_model(tmp_path)
    truncate(model / "model.onnx")
    result = run_script("evaluate.py", str(model), "--backend", "onnx", "--episodes", "1")
    assert result.returncode == 2 and "Traceback" not in result.stderr, result.stderr
    assert str(model / "model.onnx") in result.stderr


def test_onnx_backend_loads_no_pickle(tmp_path):
    """Only meta.json and model.onnx are read: no pickle is opened or unpickled, and neither torch
    nor Stable-Baselines3 is imported. Checked with Python's audit hooks in a fresh interpreter,
    on a directory that holds nothing else."""
    model = tmp_path / "model"
    model.mkdir()
    for name in ("meta.json", "model.onnx"):
        shutil.copy(REACH / name, model / name)
    probe = f"""
import sys
opened, unpickled = [], []
def hook(event, args):
    if event == "open" and isinstance(args[0], str):
        opened.append(args[0])
    elif event == "pickle.find_class":
        unpickled.append(args)
sys.addaudithook(hook)
import numpy as np
from fr5_rl.deploy.policy import load_policy
policy = load_policy({str(model)!r}, "onnx")
action = policy.act(np.zeros(policy.observation_size, dtype=np.float32))
assert action.shape == (7,)
read = sorted(p for p in opened if p.startswith({str(model)!r}))
print(read)
assert set(read) <= {{{str(model / 'meta.json')!r}, {str(model / 'model.onnx')!r}}}, read
assert not unpickled, unpickled
assert not any(p.endswith((".pkl", ".zip")) for p in opened), [p for p in opened if p.endswith((".pkl", ".zip"))]
for heavy in ("torch", "stable_baselines3"):
    assert heavy not in sys.modules, heavy + " was imported"
print("ok")
"""
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0 and result.stdout.strip().endswith("ok"), result.stdout + result.stderr
    assert str(model / "meta.json") in result.stdout  # the hook sees what Python opens (onnxruntime reads in C++)


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def wait_for_master(uri: str, core: subprocess.Popen, timeout: float = 60.0) -> None:
    """Block until the ROS master at ``uri`` answers as a master. A node started before that
    may reach roscore's start-up half-done (CI once saw 'method "setParam" is not supported')."""
    import xmlrpc.client

    deadline = time.monotonic() + timeout
    while True:
        try:
            code, _, _ = xmlrpc.client.ServerProxy(uri).getPid("/test_model_files")
            if code == 1:
                return
        except (OSError, xmlrpc.client.Fault, xmlrpc.client.ProtocolError):
            pass
        assert core.poll() is None, f"roscore at {uri} exited with {core.returncode}"
        assert time.monotonic() < deadline, f"no ROS master answered at {uri} within {timeout:g} s"
        time.sleep(0.2)


@pytest.mark.slow  # starts a roscore and the node
def test_policy_node_logs_fatal_and_exits_nonzero(tmp_path):
    """A real roscore; the node is started as a user would, on a damaged model."""
    model = copy_model(tmp_path)
    garbage(model / "vecnormalize.pkl")
    env = dict(os.environ, ROS_MASTER_URI=f"http://127.0.0.1:{free_port()}", ROS_LOG_DIR=str(tmp_path / "log"))
    port = env["ROS_MASTER_URI"].rsplit(":", 1)[1]
    core = subprocess.Popen(["roscore", "-p", port], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        wait_for_master(env["ROS_MASTER_URI"], core)
        result = subprocess.run(["rosrun", "fr5_rl", "policy_node.py", f"_model_dir:={model}", "_backend:=torch"],
                                env=env, capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)
    finally:
        core.terminate()
        core.wait(timeout=30)
    output = result.stdout + result.stderr
    assert result.returncode != 0, output
    fatal = [line for line in output.splitlines() if "FATAL" in line]
    assert fatal and str(model / "vecnormalize.pkl") in fatal[0], output
    assert "Traceback" not in output, output


def test_a_ctrl_c_during_a_save_takes_effect_once_the_save_is_done():
    """Ctrl-C half-way through a checkpoint used to surface as torch's zip-writer error (the
    trainer crashed instead of saving and exiting 130): the interrupt now waits for the block."""
    import signal

    from fr5_rl.deploy.bundle import interrupts_deferred

    finished = []
    outer = signal.signal(signal.SIGINT, signal.default_int_handler)  # a terminal's Python process
    try:
        with pytest.raises(KeyboardInterrupt):
            with interrupts_deferred():
                os.kill(os.getpid(), signal.SIGINT)
                finished.append("the rest of the save")
        assert finished == ["the rest of the save"]
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # the handler is back
        with interrupts_deferred():  # no Ctrl-C: nothing happens afterwards
            finished.append("a quiet save")
        assert finished[-1] == "a quiet save"
    finally:
        signal.signal(signal.SIGINT, outer)
