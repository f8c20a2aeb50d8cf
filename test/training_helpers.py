"""What the training tests share: small hyperparameter files, a trainer in a subprocess, waiting
for its checkpoint, and the checks of a model directory."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
TRAIN_SCRIPT = REPO / "scripts" / "train.py"
# The same entry point as scripts/train.py, but passing main()'s return value to sys.exit.
TRAIN_MODULE = ["-c", "import sys; from fr5_rl.cli.train import main; sys.exit(main(sys.argv[1:]))"]

FAST_PPO = """\
n_timesteps: 20000
n_envs: 2
normalize: {norm_obs: true, norm_reward: false, clip_obs: 10.0}
env: {}
algo_kwargs:
  policy: MlpPolicy
  n_steps: 256
  batch_size: 128
  n_epochs: 2
  learning_rate: 0.0003
  gamma: 0.98
  policy_kwargs:
    net_arch: {pi: [32, 32], vf: [32, 32]}
"""

# The default PPO reach model (the ppo_run fixture) carries the joint-step hint: 23 + 6 values.
DEFAULT_REACH_SIZE = 29
# FAST_PPO with the default reach config's observation: a run that can start from ppo_run's model.
FAST_PPO_WITH_HINT = FAST_PPO.replace(
    "env: {}", "env: {observation: {joint_step_hint: "
    "{cartesian_step: 0.015, rotation_step: 0.05, damping: 0.05, joint_step_scale: 0.04}}}")

OFF_POLICY = """\
n_timesteps: 600
n_envs: 1
normalize: {norm_obs: true, norm_reward: false, clip_obs: 10.0}
env: {}
algo_kwargs:
  policy: MlpPolicy
  learning_rate: 0.001
  buffer_size: 2000
  batch_size: 32
  learning_starts: 100
  gamma: 0.98
  train_freq: 4
  gradient_steps: 1
  policy_kwargs: {net_arch: [32, 32]}
"""


def write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def read_json(path: Path) -> dict:
    return json.loads(Path(path).read_text(encoding="utf-8"))


def subprocess_env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = f"{REPO / 'src'}{os.pathsep}{env.get('PYTHONPATH', '')}"
    env["PYTHONUNBUFFERED"] = "1"
    return env


def start_training(command_prefix, run_dir: Path, hyperparams: Path, timesteps: int, extra=(),
                   new_session=False) -> subprocess.Popen:
    args = [sys.executable, *command_prefix, "--timesteps", str(timesteps), "--n-envs", "2",
            "--hyperparams", str(hyperparams), "--checkpoint-freq", "1000", "--eval-freq", "1000000",
            "--eval-episodes", "1", "--no-progress", "--run-dir", str(run_dir), *extra]
    return subprocess.Popen(args, cwd=REPO, env=subprocess_env(), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=new_session,
                            preexec_fn=default_sigint)


def default_sigint() -> None:
    """Children of a background job inherit an ignored SIGINT (and Python then installs no
    KeyboardInterrupt handler); give the trainer the disposition an interactive user has."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def wait_for_checkpoint(proc: subprocess.Popen, run_dir: Path, timeout: float = 45.0) -> int:
    """Wait until checkpoints/latest is complete; returns its num_timesteps."""
    meta = run_dir / "checkpoints" / "latest" / "meta.json"
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if meta.is_file():
            try:
                return int(read_json(meta)["num_timesteps"])
            except (OSError, ValueError, KeyError):
                pass  # being replaced right now
        if proc.poll() is not None:
            out, err = proc.communicate()
            pytest.fail(f"training exited early with {proc.returncode}:\n{out}\n{err}")
        time.sleep(0.05)
    proc.kill()
    out, err = proc.communicate()
    pytest.fail(f"no checkpoint after {timeout} s:\n{out}\n{err}")


def assert_model_dir(directory: Path, task="reach", algo="ppo") -> dict:
    for name in ("model.zip", "vecnormalize.pkl", "meta.json"):
        assert (directory / name).is_file() and (directory / name).stat().st_size > 0, name
    meta = read_json(directory / "meta.json")
    assert meta["task"] == task and meta["algo"] == algo
    hint = 6 if meta["env_config"]["observation"].get("joint_step_hint") else 0  # the joint-step hint's block
    assert meta["observation_size"] == (23 if task == "reach" else 24) + hint and meta["action_size"] == 7
    return meta
