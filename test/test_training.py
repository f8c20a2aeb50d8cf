"""Tests of training, checkpoints, resuming, evaluation, loading and ONNX export.

Short runs only (seconds each): they check the plumbing (files written, resumability,
interrupt handling, refusals, numerical parity), not learning quality.
"""
from __future__ import annotations

import csv
import dataclasses
import json
import os
import signal
import time
from pathlib import Path

import numpy as np
import pytest

from fr5_rl.config import ConfigError, package_root
from fr5_rl.cli import evaluate, train
from fr5_rl.training import evaluation
from fr5_rl.training.algorithms import check_hyperparameters, load_hyperparameters
from fr5_rl.training.run_settings import FIXED_ON_RESUME, KEPT_ON_RESUME, TrainRun
from fr5_rl.deploy.bundle import ModelFilesError
from training_helpers import (DEFAULT_REACH_SIZE, FAST_PPO, OFF_POLICY, TRAIN_MODULE, TRAIN_SCRIPT, assert_model_dir,
                              read_json, start_training, wait_for_checkpoint, write)

pytestmark = pytest.mark.slow  # short training runs, resumes and Ctrl-C in subprocesses: `make test`, not `make test-fast`

def test_short_ppo_run_writes_checkpoint(ppo_run):
    latest = ppo_run / "checkpoints" / "latest"
    meta = assert_model_dir(latest)
    assert meta["observation_size"] == DEFAULT_REACH_SIZE  # config/ppo_reach.yaml turns the hint on
    assert meta["num_timesteps"] >= 6000
    assert meta["control_dt"] == 0.02
    assert_model_dir(ppo_run / "final")
    config = read_json(ppo_run / "config.json")
    assert config["timesteps"] == 6000 and config["n_envs"] == 32 and config["algo"] == "ppo"
    summary = read_json(ppo_run / "summary.json")
    assert summary["finished"] is True and summary["num_timesteps"] == meta["num_timesteps"]
    assert len(summary["eval_history"]) >= 2  # --eval-freq 1000 over 6000 steps
    assert (ppo_run / "eval" / "evaluations.npz").is_file()
    # no staging directories left behind
    assert not [p.name for p in (ppo_run / "checkpoints").iterdir() if p.name.startswith(".")]
    # The statistics are real running statistics, not the initial ones.
    from fr5_rl.deploy.policy import load_normalizer

    normalizer = load_normalizer(latest)
    assert normalizer.obs_rms.count > 1000
    assert np.any(np.abs(normalizer.obs_rms.mean) > 1e-3)


def test_monitor_logs_episodes(ppo_run):
    """SB3 Monitor files: a '#{json}' line, the CSV header, then one row per episode."""
    files = sorted((ppo_run / "monitor").glob("*.monitor.csv"))
    assert len(files) == 32  # one per environment
    rows = []
    for path in files:
        lines = path.read_text(encoding="utf-8").splitlines()
        assert lines and lines[0].startswith("#{"), f"{path.name} lacks the Monitor header: {lines[:2]}"
        assert lines[1].split(",") == ["r", "l", "t", "is_success", "failure"]
        rows += list(csv.DictReader(lines[1:]))
    assert len(rows) >= 10
    assert sum(int(row["l"]) for row in rows) <= 6144


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


def test_evaluation_spread_over_processes_evaluates_the_same_episodes(tmp_path):
    """The evaluation's environments step on every core like the training ones; how many
    processes step them changes nothing: each environment is seeded by its rank, and each
    evaluation runs ``--eval-episodes`` episodes spread over ``--eval-envs`` of them."""
    import numpy as np

    evaluations = {}
    for processes in ("1", "2"):
        run_dir = tmp_path / f"processes_{processes}"
        code = train.main(["--timesteps", "1024", "--n-envs", "2", "--processes", processes, "--eval-freq", "512",
                           "--eval-episodes", "3", "--eval-envs", "2", "--no-progress", "--run-dir", str(run_dir),
                           "--hyperparams", str(write(tmp_path / "ppo_fast.yaml", FAST_PPO))])
        assert code == 0
        with np.load(run_dir / "eval" / "evaluations.npz") as saved:
            evaluations[processes] = (saved["results"], saved["ep_lengths"])
    results, lengths = evaluations["1"]
    assert lengths.shape == (2, 3)  # two evaluations of three episodes
    assert np.array_equal(results, evaluations["2"][0]) and np.array_equal(lengths, evaluations["2"][1])
    # and the setting takes effect: one environment plays other episodes (rank 1's are not among them)
    run_dir = tmp_path / "one_env"
    assert train.main(["--timesteps", "1024", "--n-envs", "2", "--processes", "2", "--eval-freq", "512",
                       "--eval-episodes", "3", "--eval-envs", "1", "--no-progress", "--run-dir", str(run_dir),
                       "--hyperparams", str(tmp_path / "ppo_fast.yaml")]) == 0
    with np.load(run_dir / "eval" / "evaluations.npz") as saved:
        assert not np.array_equal(saved["results"], results)
    assert read_json(tmp_path / "processes_2" / "config.json")["eval_envs"] == 2  # a resume keeps it


@pytest.mark.parametrize("option", [["--eval-min-training-success", "1.5"], ["--eval-min-training-success", "-0.1"],
                                    ["--eval-envs", "0"], ["--eval-episodes", "0"]])
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


SAVED_CONFIG = {"task": "grasp", "algo": "tqc", "seed": 7, "n_envs": 3, "timesteps": 9000, "hyperparams_resolved": {},
                "checkpoint_freq": 500, "eval_freq": 1500, "eval_episodes": 5, "no_subprocess": True,
                "target_success": 0.8, "eval_min_training_success": 0.25}


def test_resume_merge_takes_the_saved_run_but_for_options_typed_again():
    given = TrainRun(task="reach", algo="ppo", seed=1, n_envs=8, timesteps=100, run_dir=Path("r"), resume=True,
                     eval_freq=20_000, target_success=0.5, processes=2, progress=False, torch_threads=3)
    merged = given.resumed(SAVED_CONFIG, typed_again={"task", "seed", "eval_freq", "target_success", "processes"})
    # what the run is comes from config.json, typed again or not
    assert (merged.task, merged.algo, merged.seed, merged.n_envs, merged.timesteps) == ("grasp", "tqc", 7, 3, 9000)
    # typed again: this resumption's values, even one equal to its default (eval_freq 20000)
    assert (merged.eval_freq, merged.target_success) == (20_000, 0.5)
    # not typed again: the run's own
    assert (merged.checkpoint_freq, merged.eval_episodes, merged.subprocess, merged.eval_min_training_success) == \
        (500, 5, False, 0.25)
    # never saved: as given
    assert (merged.processes, merged.progress, merged.torch_threads, merged.run_dir) == (2, False, 3, Path("r"))
    # nothing typed again (a Ray trial's retry): all of config.json; a config.json without the newer keys
    older = {key: value for key, value in SAVED_CONFIG.items() if key != "eval_min_training_success"}
    plain = TrainRun(resume=True, eval_min_training_success=0.5).resumed(older, frozenset())
    assert (plain.eval_freq, plain.subprocess, plain.eval_min_training_success) == (1500, False, 0.5)
    assert plain.eval_envs == 1  # evaluated in one environment before the key existed: it goes on so
    # and config.json written back reads the same
    assert TrainRun().resumed(merged.saved_config({}), set()) == dataclasses.replace(TrainRun(), **{
        name: getattr(merged, name) for name in FIXED_ON_RESUME + KEPT_ON_RESUME})
    with pytest.raises(ValueError, match="no_progress"):
        given.resumed(SAVED_CONFIG, {"no_progress"})  # option names must be TrainRun fields


def test_typed_options_are_what_the_command_line_gives():
    parser = train.build_parser()
    assert train.typed_options(parser, []) == set()
    assert train.typed_options(parser, ["--resume", "--run-dir", "r", "--eval-freq", "20000", "--no-subprocess"]) == \
        {"resume", "run_dir", "eval_freq", "no_subprocess"}
    assert train.train_run(parser.parse_args([])) == TrainRun()  # the command line's defaults are TrainRun's


def test_resumed_run_keeps_its_settings_unless_typed_again(ppo_run, tmp_path, monkeypatch):
    """train.py --resume hands train() the run's saved settings, and the options typed again."""
    import fr5_rl.training.train as training

    seen = []
    monkeypatch.setattr(training, "train", lambda run, t_start=None, extra_callbacks=None: seen.append(run) or 0)
    common = ["--resume", "--run-dir", str(ppo_run), "--no-progress"]
    assert train.main([*common, "--n-envs", "5", "--eval-freq", "20000"]) == 0
    assert train.main(common) == 0
    typed_again, plain = seen
    assert typed_again.n_envs == plain.n_envs == 32 and plain.eval_freq == 1000 and typed_again.eval_freq == 20_000
    assert plain.checkpoint_freq == typed_again.checkpoint_freq == 1000 and plain.eval_episodes == 2


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


def test_batch_error_suggests_settings_that_are_accepted():
    """The default reach config (32 x 16 steps, batch 512) with fewer environments: the error
    names an n_steps and a batch_size, and each, set alone, is accepted."""
    import dataclasses
    import re

    shipped = load_hyperparameters("ppo", "reach")
    for n_envs in (1, 4, 5):
        with pytest.raises(ConfigError) as refused:
            check_hyperparameters("ppo", shipped, n_envs)
        message = str(refused.value)
        for key in ("n_steps", "batch_size"):
            value = int(re.search(rf"algo_kwargs\.{key}: (\d+)", message).group(1))
            fixed = dataclasses.replace(shipped, algo_kwargs={**shipped.algo_kwargs, key: value})
            check_hyperparameters("ppo", fixed, n_envs)


def test_shipped_hyperparameters_pass_their_checks():
    # <algo>_<task>.yaml, and the recipes' stages and variants such as recipes/ppo_reach_finetune.yaml
    config = package_root() / "config"
    shipped = [(path.stem.split("_"), path) for path in [*config.glob("*_*.yaml"), *config.glob("recipes/*_*.yaml")]
               if path.stem.split("_")[0] in ("ppo", "sac", "td3", "tqc")]
    assert ["ppo", "reach"] in [parts for parts, _ in shipped]
    assert ["ppo", "grasp", "fr5"] in [parts for parts, _ in shipped]  # the shipped grasp model's last stage
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
    from fr5_rl.deploy.policy import load_policy

    (model_copy / "vecnormalize.pkl").unlink()
    with pytest.raises(ModelFilesError, match="statistics"):
        load_policy(model_copy, "torch")  # the onnx backend needs no pickle: test_model_files.py


def test_missing_directory_and_model_refused(model_copy, tmp_path):
    from fr5_rl.deploy.policy import load_policy

    with pytest.raises(ModelFilesError):
        load_policy(tmp_path / "does_not_exist")
    (model_copy / "model.zip").unlink()
    with pytest.raises(ModelFilesError, match="model.zip"):
        load_policy(model_copy)


def test_observation_size_mismatch_refused(model_copy):
    from fr5_rl.deploy.policy import load_policy

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
    from fr5_rl.deploy.policy import load_policy
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
    assert summary["training_steps"] >= 6000
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
