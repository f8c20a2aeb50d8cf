"""Tests of training, checkpoints, resuming, evaluation, loading and ONNX export.

Short runs only (seconds each): they check the plumbing (files written, resumability,
interrupt handling, refusals, numerical parity), not learning quality.
"""
from __future__ import annotations

import csv
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from fr5_rl.config import ConfigError, package_root
from fr5_rl.cli import evaluate, train
from fr5_rl.training import evaluation
from fr5_rl.training.algorithms import check_hyperparameters, load_hyperparameters
from fr5_rl.training.curriculum import STATE_FILE
from fr5_rl.runtime.bundle import ModelFilesError

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


# ----------------------------------------------------------------------------- a short PPO run
@pytest.fixture(scope="module")
def ppo_run(tmp_path_factory) -> Path:
    run_dir = tmp_path_factory.mktemp("ppo") / "run"
    code = train.main(["--timesteps", "3000", "--n-envs", "2", "--no-subprocess", "--checkpoint-freq", "1000",
                       "--eval-freq", "1000", "--eval-episodes", "2", "--no-progress", "--run-dir", str(run_dir)])
    assert code == 0
    return run_dir


@pytest.fixture
def model_copy(ppo_run, tmp_path) -> Path:
    """A private copy of the run's checkpoint, free to be damaged by the test."""
    target = tmp_path / "model"
    shutil.copytree(ppo_run / "checkpoints" / "latest", target)
    return target


def test_short_ppo_run_writes_checkpoint(ppo_run):
    latest = ppo_run / "checkpoints" / "latest"
    meta = assert_model_dir(latest)
    assert meta["observation_size"] == DEFAULT_REACH_SIZE  # config/ppo_reach.yaml turns the hint on
    assert meta["num_timesteps"] >= 3000
    assert meta["control_dt"] == 0.02
    assert_model_dir(ppo_run / "final")
    config = read_json(ppo_run / "config.json")
    assert config["timesteps"] == 3000 and config["n_envs"] == 2 and config["algo"] == "ppo"
    summary = read_json(ppo_run / "summary.json")
    assert summary["finished"] is True and summary["num_timesteps"] == meta["num_timesteps"]
    assert len(summary["eval_history"]) >= 2  # --eval-freq 1000 over 3000 steps
    assert (ppo_run / "eval" / "evaluations.npz").is_file()
    # no staging directories left behind
    assert not [p.name for p in (ppo_run / "checkpoints").iterdir() if p.name.startswith(".")]
    # The statistics are real running statistics, not the initial ones.
    from fr5_rl.runtime.policy import load_normalizer

    normalizer = load_normalizer(latest)
    assert normalizer.obs_rms.count > 1000
    assert np.any(np.abs(normalizer.obs_rms.mean) > 1e-3)


def test_monitor_logs_episodes(ppo_run):
    """SB3 Monitor files: a '#{json}' line, the CSV header, then one row per episode."""
    files = sorted((ppo_run / "monitor").glob("*.monitor.csv"))
    assert len(files) == 2  # one per environment
    rows = []
    for path in files:
        lines = path.read_text(encoding="utf-8").splitlines()
        assert lines and lines[0].startswith("#{"), f"{path.name} lacks the Monitor header: {lines[:2]}"
        assert lines[1].split(",") == ["r", "l", "t", "is_success", "failure"]
        rows += list(csv.DictReader(lines[1:]))
    assert len(rows) >= 10
    assert sum(int(row["l"]) for row in rows) <= 3072


def test_gated_evaluation_skips_until_training_episodes_succeed(tmp_path):
    """A random reach policy never succeeds, so a gate of 50 % skips every evaluation, and the
    run says how many it skipped; with the gate at 0 the same run evaluates every time."""
    histories = {}
    for gate in ("0.5", "0"):
        run_dir = tmp_path / f"gate_{gate}"
        code = train.main(["--timesteps", "2048", "--n-envs", "2", "--no-subprocess", "--eval-freq", "512",
                           "--eval-episodes", "1", "--no-progress", "--run-dir", str(run_dir),
                           "--hyperparams", str(write(tmp_path / "ppo_fast.yaml", FAST_PPO)),
                           "--eval-min-training-success", gate])
        assert code == 0
        summary = read_json(run_dir / "summary.json")
        histories[gate] = (summary.get("eval_history", []), summary["evaluations_skipped"])
    assert histories["0.5"] == ([], 4)
    assert len(histories["0"][0]) == 4 and histories["0"][1] == 0


@pytest.mark.parametrize("option", [["--eval-min-training-success", "1.5"], ["--eval-min-training-success", "-0.1"]])
def test_evaluation_options_are_checked(option, tmp_path, capsys):
    code = train.main(["--timesteps", "1000", "--no-progress", "--run-dir", str(tmp_path / "run"), *option])
    assert code == 2
    assert option[0] in capsys.readouterr().err


# ----------------------------------------------------------------------------- kill and resume
def test_killed_run_resumes(tmp_path, capsys):
    run_dir = tmp_path / "run"
    hyper = write(tmp_path / "ppo_fast.yaml", FAST_PPO)
    proc = start_training([str(TRAIN_SCRIPT)], run_dir, hyper, 20000, extra=["--no-subprocess"])
    try:
        wait_for_checkpoint(proc, run_dir)
        time.sleep(0.3)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.communicate(timeout=30)
    assert proc.returncode == -signal.SIGKILL
    assert not (run_dir / "final").exists(), "the run finished before it could be killed"
    killed_at = assert_model_dir(run_dir / "checkpoints" / "latest")["num_timesteps"]
    assert 0 < killed_at < 20000
    monitor_files = sorted((run_dir / "monitor").glob("*.monitor.csv"))
    lines_before = [len(path.read_text().splitlines()) for path in monitor_files]

    code = train.main(["--resume", "--run-dir", str(run_dir), "--no-subprocess", "--no-progress",
                       "--checkpoint-freq", "5000", "--eval-freq", "1000000"])
    assert code == 0
    out = capsys.readouterr().out
    assert f"resuming {run_dir} from step {killed_at}" in out
    final = assert_model_dir(run_dir / "final")
    assert final["num_timesteps"] >= 20000 >= killed_at
    latest = assert_model_dir(run_dir / "checkpoints" / "latest")
    assert latest["num_timesteps"] == final["num_timesteps"]
    summary = read_json(run_dir / "summary.json")
    assert summary["finished"] is True and summary["num_timesteps"] == final["num_timesteps"]
    # the episode logs were appended to, not restarted (and no second header)
    for path, before in zip(monitor_files, lines_before):
        lines = path.read_text().splitlines()
        assert len(lines) > before
        assert sum(line.startswith("#") for line in lines) <= 1


def test_resume_needs_existing_run(tmp_path, capsys):
    assert train.main(["--resume", "--run-dir", str(tmp_path / "nothing"), "--no-progress"]) == 2
    assert "--resume" in capsys.readouterr().err


# ----------------------------------------------------------------------------- Ctrl-C
@pytest.mark.parametrize("entry", ["scripts/train.py", "train.main"])
def test_sigint_saves_checkpoint_and_exits_130(tmp_path, entry):
    run_dir = tmp_path / "run"
    hyper = write(tmp_path / "ppo_fast.yaml", FAST_PPO)
    prefix = [str(TRAIN_SCRIPT)] if entry == "scripts/train.py" else TRAIN_MODULE
    proc = start_training(prefix, run_dir, hyper, 1_000_000, extra=["--no-subprocess"])
    try:
        before = wait_for_checkpoint(proc, run_dir)
        time.sleep(0.5)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert "interrupted; saving a checkpoint" in err, err
    after = assert_model_dir(run_dir / "checkpoints" / "latest")["num_timesteps"]
    assert after >= before
    summary = read_json(run_dir / "summary.json")
    assert summary["finished"] is False and summary["num_timesteps"] == after
    assert not (run_dir / "final").exists()
    assert proc.returncode == 130, f"exit code {proc.returncode}\n{out}\n{err[-2000:]}"


def test_ctrl_c_in_terminal_with_subprocess_envs(tmp_path):
    """Ctrl-C in a terminal signals the whole process group: the SubprocVecEnv workers too."""
    run_dir = tmp_path / "run"
    hyper = write(tmp_path / "ppo_fast.yaml", FAST_PPO)
    proc = start_training(TRAIN_MODULE, run_dir, hyper, 1_000_000, new_session=True)
    try:
        before = wait_for_checkpoint(proc, run_dir, timeout=55)
        time.sleep(0.5)
        os.killpg(proc.pid, signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
    after = assert_model_dir(run_dir / "checkpoints" / "latest")["num_timesteps"]
    assert after >= before
    assert proc.returncode == 130, f"exit code {proc.returncode}\n{err[-3000:]}"


# ----------------------------------------------------------------------------- configuration checks
def test_ppo_divisibility_check(tmp_path, capsys):
    hyper = write(tmp_path / "bad.yaml", FAST_PPO.replace("n_steps: 256", "n_steps: 100")
                  .replace("batch_size: 128", "batch_size: 64"))
    run_dir = tmp_path / "run"
    code = train.main(["--hyperparams", str(hyper), "--n-envs", "2", "--timesteps", "1000",
                       "--no-subprocess", "--no-progress", "--run-dir", str(run_dir)])
    assert code == 2
    err = capsys.readouterr().err
    assert "batch_size=64" in err and "200" in err, err  # 100 steps * 2 envs
    assert not run_dir.exists(), "the check must fire before any run directory or training"
    # the same file with 4 environments (400 samples) is divisible by 64? no; by 80: yes
    data = load_hyperparameters("ppo", "reach", str(hyper))
    with pytest.raises(ConfigError, match="batch_size"):
        check_hyperparameters("ppo", data, 4)
    data.algo_kwargs["batch_size"] = 80
    check_hyperparameters("ppo", data, 4)  # 400 % 80 == 0: accepted


def test_shipped_hyperparameters_pass_their_checks():
    # <algo>_<task>.yaml, and variants such as ppo_reach_finetune.yaml
    shipped = [(path.stem.split("_"), path) for path in (package_root() / "config").glob("*_*.yaml")
               if path.stem.split("_")[0] in ("ppo", "sac", "td3", "tqc")]
    assert ["ppo", "reach"] in [parts for parts, _ in shipped]
    for (algo, task, *_variant), path in shipped:
        hyper = load_hyperparameters(algo, task, str(path))
        check_hyperparameters(algo, hyper, hyper.n_envs)
        assert hyper.n_timesteps > 0


def test_a_hyperparameter_file_builds_on_its_base(tmp_path):
    """``base:`` merges the named file under this one: nested keys are replaced one by one,
    keys the base lacks are added, and the stage-3 grasp file is the robust file plus its lag."""
    robust = load_hyperparameters("ppo", "grasp", "ppo_grasp_robust").to_dict()
    stage3 = load_hyperparameters("ppo", "grasp", "ppo_grasp_robust_stage3").to_dict()
    assert stage3["env"]["randomisation"]["action_latency_steps"] == [1, 2]
    assert stage3["n_timesteps"] == 2_000_000
    robust["env"]["randomisation"]["action_latency_steps"], robust["n_timesteps"] = [1, 2], 2_000_000
    assert stage3 == robust
    child = write(tmp_path / "child.yaml", f"base: {tmp_path / 'parent.yaml'}\nn_envs: 4\n"
                  "algo_kwargs: {n_steps: 128}\ncritic_warmup: {steps: 100, learning_rate: 0.001}\n")
    write(tmp_path / "parent.yaml", FAST_PPO)
    merged = load_hyperparameters("ppo", "reach", child)
    assert merged.n_envs == 4 and merged.algo_kwargs["n_steps"] == 128 and merged.algo_kwargs["n_epochs"] == 2
    assert merged.critic_warmup is not None and merged.critic_warmup.steps == 100


def test_hyperparameter_bases_that_loop_or_are_missing_are_refused(tmp_path):
    first = write(tmp_path / "first.yaml", f"base: {tmp_path / 'second.yaml'}\nn_envs: 2\n")
    write(tmp_path / "second.yaml", f"base: {first}\nn_envs: 3\n")
    with pytest.raises(ConfigError, match="leads back to itself"):
        load_hyperparameters("ppo", "reach", first)
    lonely = write(tmp_path / "lonely.yaml", "base: no_such_file\nn_envs: 2\n")
    with pytest.raises(ConfigError, match="not found"):
        load_hyperparameters("ppo", "reach", lonely)


def test_off_policy_batch_larger_than_buffer_refused(tmp_path):
    data = load_hyperparameters("sac", "reach", str(write(tmp_path / "sac.yaml", OFF_POLICY)))
    data.algo_kwargs["batch_size"] = 5000
    with pytest.raises(ConfigError, match="batch_size"):
        check_hyperparameters("sac", data, 1)


# ----------------------------------------------------------------------------- loading
def test_missing_statistics_refused(model_copy):
    from fr5_rl.runtime.policy import load_policy

    (model_copy / "vecnormalize.pkl").unlink()
    with pytest.raises(ModelFilesError, match="statistics"):
        load_policy(model_copy, "torch")  # the onnx backend needs no pickle: test_model_files.py


def test_missing_directory_and_model_refused(model_copy, tmp_path):
    from fr5_rl.runtime.policy import load_policy

    with pytest.raises(ModelFilesError):
        load_policy(tmp_path / "does_not_exist")
    (model_copy / "model.zip").unlink()
    with pytest.raises(ModelFilesError, match="model.zip"):
        load_policy(model_copy)


def test_observation_size_mismatch_refused(model_copy):
    from fr5_rl.runtime.policy import load_policy

    policy = load_policy(model_copy, "torch", expected_task="reach")
    assert policy.act(np.zeros(DEFAULT_REACH_SIZE, dtype=np.float32)).shape == (7,)
    with pytest.raises(ValueError):
        policy.act(np.zeros(23, dtype=np.float32))  # without the hint
    with pytest.raises(ValueError):
        policy.act(np.full(DEFAULT_REACH_SIZE, np.nan, dtype=np.float32))
    with pytest.raises(ModelFilesError, match="grasp"):
        load_policy(model_copy, "torch", expected_task="grasp")
    # meta.json that disagrees with model.zip
    meta = read_json(model_copy / "meta.json")
    meta["observation_size"] = 24
    (model_copy / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(ModelFilesError, match="observation"):
        load_policy(model_copy, "torch")


def test_onnx_backend_needs_export_and_checks_size(model_copy):
    from fr5_rl.runtime.policy import load_policy
    from fr5_rl.training.onnx_export import export

    with pytest.raises(ModelFilesError, match="export_onnx"):
        load_policy(model_copy, "onnx")
    export(model_copy)
    assert load_policy(model_copy, "onnx").act(np.zeros(DEFAULT_REACH_SIZE, dtype=np.float32)).shape == (7,)
    meta = read_json(model_copy / "meta.json")
    meta["observation_size"] = 24
    (model_copy / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(ModelFilesError, match="observation"):
        load_policy(model_copy, "onnx")


# ----------------------------------------------------------------------------- evaluation
def test_wilson_interval():
    assert evaluation.wilson_interval(0, 0) == (0.0, 1.0)
    low, high = evaluation.wilson_interval(5, 10)
    assert (low, high) == pytest.approx((0.2366, 0.7634), abs=1e-4)
    low, high = evaluation.wilson_interval(10, 10)
    assert low == pytest.approx(0.7225, abs=1e-4) and high == pytest.approx(1.0, abs=1e-12)
    low, high = evaluation.wilson_interval(0, 10)
    assert low == pytest.approx(0.0, abs=1e-12) and high == pytest.approx(0.2775, abs=1e-4)
    low, high = evaluation.wilson_interval(190, 200)
    assert low == pytest.approx(0.9104, abs=1e-4) and high == pytest.approx(0.9726, abs=1e-4)


def check_eval_outputs(out: Path, episodes: int) -> dict:
    summary = read_json(out)
    assert summary["episodes"] == episodes
    successes = summary["successes"]
    assert summary["success_rate"] == pytest.approx(successes / episodes)
    low, high = evaluation.wilson_interval(successes, episodes)
    assert summary["success_rate_95ci"] == pytest.approx([round(low, 4), round(high, 4)])
    assert summary["success_rate_95ci"][0] <= summary["success_rate"] <= summary["success_rate_95ci"][1]
    with open(out.with_suffix(".csv"), newline="", encoding="utf-8") as stream:
        rows = list(csv.DictReader(stream))
    assert len(rows) == episodes
    assert sum(row["success"] == "True" for row in rows) == successes
    seeds = [int(row["seed"]) for row in rows]
    assert seeds == list(range(evaluate.HELD_OUT_SEED_START, evaluate.HELD_OUT_SEED_START + episodes))
    assert summary["mean_episode_length"] == pytest.approx(np.mean([int(r["length"]) for r in rows]))
    return summary


def test_evaluate_trained_model(model_copy, tmp_path, capsys):
    out = tmp_path / "eval" / "result.json"
    assert evaluate.main([str(model_copy), "--episodes", "3", "--out", str(out)]) == 0
    summary = check_eval_outputs(out, 3)
    assert summary["task"] == "reach" and summary["algo"] == "ppo" and summary["backend"] == "torch"
    assert summary["training_steps"] >= 3000
    assert "95% CI" in capsys.readouterr().out


def test_evaluate_expert_writes_json_and_csv(tmp_path):
    out = tmp_path / "expert.json"
    assert evaluate.main(["--expert", "reach", "--episodes", "5", "--out", str(out)]) == 0
    summary = check_eval_outputs(out, 5)
    assert summary["successes"] >= 4
    assert summary["backend"] == "expert"


def test_evaluate_refuses_incomplete_model(model_copy, tmp_path, capsys):
    (model_copy / "vecnormalize.pkl").unlink()
    assert evaluate.main([str(model_copy), "--episodes", "1", "--out", str(tmp_path / "e.json")]) == 2
    assert "statistics" in capsys.readouterr().err
    assert not (tmp_path / "e.json").exists()


# ----------------------------------------------------------------------------- ONNX export
def test_onnx_parity(model_copy):
    from fr5_rl.training.onnx_export import export, parity

    path = export(model_copy)
    assert path == model_copy / "model.onnx" and path.stat().st_size > 0
    worst = parity(model_copy, 1000)
    assert worst <= 1e-5, worst


def test_onnx_parity_detects_a_wrong_graph(model_copy):
    """The parity check can fail: export, then change the statistics under the graph."""
    import pickle

    from fr5_rl.training.onnx_export import export, parity

    export(model_copy)
    with open(model_copy / "vecnormalize.pkl", "rb") as stream:
        normalizer = pickle.load(stream)
    normalizer.obs_rms.mean = normalizer.obs_rms.mean + 0.5
    normalizer.class_attributes, normalizer.returns = {}, None  # dropped by VecNormalize's pickling
    with open(model_copy / "vecnormalize.pkl", "wb") as stream:
        pickle.dump(normalizer, stream)
    assert parity(model_copy, 50) > 1e-3


# ----------------------------------------------------------------------------- off-policy algorithms
@pytest.mark.parametrize("algo", ["sac", "td3", "tqc"])
def test_off_policy_short_run(algo, tmp_path):
    from fr5_rl.training.onnx_export import export, parity

    run_dir = tmp_path / "run"
    hyper = write(tmp_path / f"{algo}.yaml", OFF_POLICY)
    code = train.main(["--algo", algo, "--hyperparams", str(hyper), "--timesteps", "600", "--n-envs", "1",
                       "--no-subprocess", "--checkpoint-freq", "300", "--eval-freq", "300",
                       "--eval-episodes", "1", "--no-progress", "--run-dir", str(run_dir)])
    assert code == 0
    latest = run_dir / "checkpoints" / "latest"
    meta = assert_model_dir(latest, algo=algo)
    assert meta["num_timesteps"] >= 600
    assert (latest / "replay_buffer.pkl").is_file()
    assert_model_dir(run_dir / "final", algo=algo)
    # the exported actor matches SB3 for this algorithm too
    export(latest)
    assert parity(latest, 200) <= 1e-5


# ----------------------------------------------------------------------------- --init-from (fine-tuning)
def test_init_from_continues_the_given_model(ppo_run, tmp_path):
    """A fine-tuning run starts from the given weights and statistics (not from scratch) and
    counts its own steps; its meta says where it came from."""
    import torch
    from stable_baselines3 import PPO

    source = ppo_run / "checkpoints" / "latest"
    run_dir = tmp_path / "fine"
    code = train.main(["--init-from", str(source), "--timesteps", "512", "--n-envs", "2", "--no-subprocess",
                       "--checkpoint-freq", "256", "--eval-freq", "100000", "--no-progress", "--run-dir", str(run_dir)])
    assert code == 0
    meta = read_json(run_dir / "final" / "meta.json")
    assert meta["initialised_from"]["model"] == str(source) and meta["initialised_from"]["num_timesteps"] >= 3000
    assert 512 <= meta["num_timesteps"] < 3000  # this run's steps only
    before = PPO.load(source / "model.zip", device="cpu").policy.state_dict()
    after = PPO.load(run_dir / "final" / "model.zip", device="cpu").policy.state_dict()
    moved = [float((after[k] - before[k]).abs().max()) for k in before if before[k].dtype == torch.float32]
    assert max(moved) > 0.0  # it trained ...
    assert max(moved) < 0.5  # ... a little, from the source's weights (a fresh init is far away)


def test_init_from_applies_this_runs_settings_and_warms_the_critic_up(ppo_run, tmp_path):
    """--init-from with a hyperparameter file: the file's training settings (learning rate,
    n_steps, clip range) replace the saved model's; with critic_warmup, the actor's weights stay
    exactly as they were while only the value function learns, then the actor trains too."""
    import torch
    from stable_baselines3 import PPO

    source = ppo_run / "checkpoints" / "latest"
    hyper = write(tmp_path / "fine.yaml", FAST_PPO_WITH_HINT.replace("n_steps: 256", "n_steps: 128")
                  .replace("learning_rate: 0.0003", "learning_rate: 0.00002")
                  + "  clip_range: 0.05\n" + "critic_warmup: {steps: 256, learning_rate: 0.001}\n")

    def fine_tune(timesteps: int) -> dict:
        run_dir = tmp_path / f"fine_{timesteps}"
        code = train.main(["--init-from", str(source), "--hyperparams", str(hyper), "--timesteps", str(timesteps),
                           "--n-envs", "1", "--no-subprocess", "--eval-freq", "100000", "--no-progress",
                           "--run-dir", str(run_dir)])
        assert code == 0
        return PPO.load(run_dir / "final" / "model.zip", device="cpu")

    before = PPO.load(source / "model.zip", device="cpu").policy.state_dict()
    held = fine_tune(256)  # two rollouts of 128: both inside the warm-up
    assert (held.learning_rate, held.n_steps, held.clip_range(1.0)) == (0.00002, 128, 0.05)
    state = held.policy.state_dict()
    actor = [k for k in before if k.startswith(("mlp_extractor.policy_net", "action_net", "log_std"))]
    critic = [k for k in before if k.startswith(("mlp_extractor.value_net", "value_net"))]
    assert actor and critic
    for key in actor:
        assert torch.equal(state[key], before[key]), f"{key} moved during the critic warm-up"
    assert max(float((state[k] - before[k]).abs().max()) for k in critic) > 0.0
    released = fine_tune(768).policy.state_dict()  # the last rollouts train the actor as well
    assert max(float((released[k] - before[k]).abs().max()) for k in actor) > 0.0


def test_init_from_with_more_previous_actions_starts_from_the_same_policy(ppo_run, tmp_path):
    """A model trained without previous actions in its observation can start a run that has them:
    the widened network acts exactly as the source on every observation, whatever the new values
    hold (their weights start at zero), and the run trains from there. The new block goes where
    the layout puts it, before the joint-step hint, which keeps its weights."""
    import gymnasium as gym
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv

    import fr5_rl  # noqa: F401
    from fr5_rl.runtime.policy import load_policy
    from fr5_rl.training.train import load_widened

    source = ppo_run / "checkpoints" / "latest"
    hint = yaml.safe_load(FAST_PPO_WITH_HINT)["env"]["observation"]["joint_step_hint"]
    observation_cfg = {"previous_actions": 2, "joint_step_hint": hint}
    venv = DummyVecEnv([lambda: gym.make("FR5Reach-v0", config={"observation": observation_cfg})])
    model, widened = load_widened(source, PPO, venv, [(23, 12)], seed=0)
    before = load_policy(source, "torch")
    rng = np.random.default_rng(0)
    for _ in range(20):
        observation = rng.uniform(-1, 1, DEFAULT_REACH_SIZE).astype(np.float32)
        previous = rng.uniform(-1, 1, 12).astype(np.float32)
        wide = np.concatenate([observation[:23], previous, observation[23:]])
        action, _ = model.predict(widened.normalize_obs(wide), deterministic=True)
        np.testing.assert_allclose(np.clip(action, -1, 1), before.act(observation), atol=1e-5)
    venv.close()

    hyper = write(tmp_path / "wide.yaml", FAST_PPO_WITH_HINT.replace("{observation: {", "{observation: {previous_actions: 2, "))
    run_dir = tmp_path / "wide"
    code = train.main(["--init-from", str(source), "--hyperparams", str(hyper), "--timesteps", "256", "--n-envs", "1",
                       "--no-subprocess", "--eval-freq", "100000", "--no-progress", "--run-dir", str(run_dir)])
    assert code == 0
    meta = read_json(run_dir / "final" / "meta.json")
    assert meta["observation_size"] == DEFAULT_REACH_SIZE + 12 and meta["initialised_from"]["model"] == str(source)
    assert load_policy(run_dir / "final", "torch").act(np.zeros(DEFAULT_REACH_SIZE + 12)).shape == (7,)


def test_critic_warmup_settings_are_checked(tmp_path):
    with pytest.raises(ConfigError, match="critic_warmup.steps"):
        load_hyperparameters("ppo", "reach", str(write(tmp_path / "a.yaml", FAST_PPO + "critic_warmup: {steps: 0, learning_rate: 0.001}\n")))
    with pytest.raises(ConfigError, match="critic_warmup"):
        load_hyperparameters("ppo", "reach", str(write(tmp_path / "b.yaml", FAST_PPO + "critic_warmup: {steps: 100}\n")))


def test_init_from_refuses_another_task(ppo_run, tmp_path, capsys):
    code = train.main(["--task", "grasp", "--init-from", str(ppo_run / "checkpoints" / "latest"), "--timesteps",
                       "256", "--n-envs", "2", "--no-subprocess", "--no-progress", "--run-dir", str(tmp_path / "r")])
    assert code == 2
    assert "task is 'reach'" in capsys.readouterr().err


def test_expert_start_settings_are_checked(tmp_path):
    for bad, key in (("{max_steps: 0, first_reach_back: 0.2, promote_at: 0.5, window: 10, step_back: 0.1, frontier_share: 0.5}", "max_steps"),
                     ("{max_steps: 70, first_reach_back: 0.0, promote_at: 0.5, window: 10, step_back: 0.1, frontier_share: 0.5}", "first_reach_back"),
                     ("{max_steps: 70, first_reach_back: 0.2, promote_at: 0.0, window: 10, step_back: 0.1, frontier_share: 0.5}", "promote_at"),
                     ("{max_steps: 70, first_reach_back: 0.2, promote_at: 0.5, window: 10, step_back: 1.5, frontier_share: 0.5}", "step_back"),
                     ("{max_steps: 70, first_reach_back: 0.2, promote_at: 0.5, window: 10, step_back: 0.1, frontier_share: 1.5}", "frontier_share"),
                     ("{max_steps: 70, first_reach_back: 0.2, promote_at: 0.5, window: 10}", "expert_start")):
        path = tmp_path / "bad.yaml"
        write(path, FAST_PPO + f"expert_start: {bad}\n")
        with pytest.raises(ConfigError, match=key):
            load_hyperparameters("ppo", "grasp", str(path))


def test_train_runs_with_expert_starts(tmp_path):
    hyperparams = write(tmp_path / "ppo_grasp.yaml", FAST_PPO + "expert_start: {max_steps: 70, first_reach_back: 0.3, "
                                                                  "promote_at: 0.5, window: 20, step_back: 0.1, "
                                                                  "frontier_share: 0.5}\n")
    run_dir = tmp_path / "run"
    code = train.main(["--task", "grasp", "--hyperparams", str(hyperparams), "--timesteps", "1024", "--no-subprocess",
                       "--no-progress", "--eval-freq", "512", "--eval-episodes", "1", "--run-dir", str(run_dir)])
    assert code == 0
    config = read_json(run_dir / "config.json")
    assert config["hyperparams_resolved"]["expert_start"]["max_steps"] == 70
    # The curriculum ran in the training loop (its reach-back is logged every rollout).
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    (logs,) = (run_dir / "tb").iterdir()
    events = EventAccumulator(str(logs))
    events.Reload()
    assert [value.value for value in events.Scalars("curriculum/reach_back")][0] == pytest.approx(0.3)
    assert read_json(run_dir / STATE_FILE)["history"][0]["reach_back"] == pytest.approx(0.3)
    # Its learning curve draws evaluation, training episodes and the reach-back.
    from fr5_rl.training.evaluation import plot_learning_curve, training_success

    steps, rate = training_success(run_dir / "monitor")
    assert steps[-1] <= 1024 and len(steps) == len(rate) and ((rate >= 0) & (rate <= 1)).all()
    assert plot_learning_curve(run_dir, tmp_path / "curve.png").stat().st_size > 10_000


def test_the_shipped_reach_model_fine_tunes_with_the_default_config_and_its_hint(tmp_path):
    """README: ``train.py --task reach --init-from models/reach``. The shipped model was trained
    without the joint-step hint that config/ppo_reach.yaml now adds: the run widens it by those 6
    values (zero weights), so it starts acting exactly as the shipped model does."""
    import gymnasium as gym
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv

    import fr5_rl  # noqa: F401
    from fr5_rl.runtime.policy import load_policy
    from fr5_rl.training.train import load_widened

    shipped = REPO / "models" / "reach"
    assert read_json(shipped / "meta.json")["observation_size"] == 23
    hint = yaml.safe_load(FAST_PPO_WITH_HINT)["env"]["observation"]
    venv = DummyVecEnv([lambda: gym.make("FR5Reach-v0", config={"observation": hint})])
    model, widened = load_widened(shipped, PPO, venv, [(23, 6)], seed=0)
    before = load_policy(shipped, "torch")
    rng = np.random.default_rng(1)
    for _ in range(20):
        observation = rng.uniform(-1, 1, 23).astype(np.float32)
        wide = np.concatenate([observation, rng.uniform(-1, 1, 6).astype(np.float32)])
        action, _ = model.predict(widened.normalize_obs(wide), deterministic=True)
        np.testing.assert_allclose(np.clip(action, -1, 1), before.act(observation), atol=1e-5)
    venv.close()

    run_dir = tmp_path / "fine"
    code = train.main(["--task", "reach", "--init-from", str(shipped), "--timesteps", "256", "--n-envs", "2",
                       "--no-subprocess", "--eval-freq", "100000", "--no-progress", "--run-dir", str(run_dir)])
    assert code == 0
    assert read_json(run_dir / "final" / "meta.json")["observation_size"] == DEFAULT_REACH_SIZE


def test_added_observation_blocks_say_where_the_new_values_go():
    from fr5_rl.training.train import added_observation_blocks

    hint = {"cartesian_step": 0.015, "rotation_step": 0.05, "damping": 0.05, "joint_step_scale": 0.04}

    def meta(size, previous=0, with_hint=False):
        return {"observation_size": size, "env_config": {"observation": {
            "previous_actions": previous, "joint_step_hint": hint if with_hint else None}}}

    assert added_observation_blocks(meta(23), meta(29, with_hint=True)) == [(23, 6)]
    assert added_observation_blocks(meta(29, with_hint=True), meta(41, 2, True)) == [(23, 12)]
    assert added_observation_blocks(meta(35, 2), meta(47, 3, True)) == [(35, 6), (35, 6)]
    assert added_observation_blocks(meta(23), meta(23)) == []  # nothing new
    assert added_observation_blocks(meta(29, with_hint=True), meta(23)) == []  # a block taken away
    assert added_observation_blocks(meta(35, 2), meta(29, 1)) == []
    assert added_observation_blocks(meta(24), meta(29, with_hint=True)) == []  # another layout (grasp)
