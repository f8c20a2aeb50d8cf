"""What a newcomer does wrong in the first hour is refused in one line, and loses nothing
(issue #51): the model decides its task and arm, nothing is written over a shipped model or a run
without --force, a run directory given as a model names the model inside it."""
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from fr5_rl.deploy.bundle import ModelFilesError, task_and_arm
from fr5_rl.deploy.policy import load_policy

REPO = Path(__file__).resolve().parent.parent


def one_line(text: str) -> str:
    lines = [line for line in text.splitlines() if line.strip()]
    assert len(lines) == 1, text
    return lines[0]


def test_the_model_decides_the_task_and_a_contradicting_one_refuses():
    meta = json.loads((REPO / "models" / "grasp" / "meta.json").read_text())
    assert task_and_arm("models/grasp") == (meta["task"], meta["robot"])
    assert task_and_arm("models/grasp", "grasp") == ("grasp", meta["robot"])
    with pytest.raises(ModelFilesError, match="trained on 'grasp', not 'reach'"):
        task_and_arm("models/grasp", "reach")
    assert task_and_arm(None) == ("reach", "fr5")


def test_evaluate_refuses_a_model_together_with_the_expert(capsys, tmp_path, monkeypatch):
    from fr5_rl.cli.evaluate import main

    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exit_:
        main(["models/reach", "--expert", "grasp", "--episodes", "1"])
    assert exit_.value.code == 2 and "not both" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_evaluate_writes_beside_the_caller_not_into_the_model(tmp_path, monkeypatch):
    from fr5_rl.cli.evaluate import main

    model = tmp_path / "models" / "reach"
    shutil.copytree(REPO / "models" / "reach", model)
    before = {path.name: path.read_bytes() for path in model.iterdir()}
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    assert main([str(model), "--episodes", "2", "--no-map"]) == 0
    assert {path.name: path.read_bytes() for path in model.iterdir()} == before
    assert json.loads((work / "eval_reach.json").read_text())["episodes"] == 2
    assert (work / "eval_reach.csv").is_file()


def test_evaluate_refuses_to_replace_a_models_result_without_force(capsys, tmp_path):
    from fr5_rl.cli.evaluate import main

    model = tmp_path / "reach"
    shutil.copytree(REPO / "models" / "reach", model)
    shipped = (model / "eval.json").read_bytes()
    assert main([str(model), "--episodes", "2", "--no-map", "--out", str(model / "eval.json")]) == 2
    assert "--force" in one_line(capsys.readouterr().err)
    assert (model / "eval.json").read_bytes() == shipped
    assert main([str(model), "--episodes", "2", "--no-map", "--out", str(model / "eval.json"), "--force"]) == 0
    assert json.loads((model / "eval.json").read_text())["episodes"] == 2


def test_a_training_run_given_as_a_model_names_the_model_inside_it(tmp_path):
    run = tmp_path / "runs" / "reach_ppo"
    shutil.copytree(REPO / "models" / "reach", run / "final")
    with pytest.raises(ModelFilesError, match=f"{run} is a training run, not a model: its model is {run / 'final'}"):
        load_policy(run, "onnx")


def test_train_refuses_a_run_directory_that_holds_a_run(capsys, tmp_path):
    from fr5_rl.cli.train import main

    run = tmp_path / "run"
    (run / "final").mkdir(parents=True)
    (run / "config.json").write_text("{}")
    assert main(["--task", "reach", "--run-dir", str(run), "--timesteps", "64", "--no-progress"]) == 2
    line = one_line(capsys.readouterr().err)
    assert "--resume" in line and "--force" in line and "new --run-dir" in line
    assert sorted(path.name for path in run.iterdir()) == ["config.json", "final"]


def test_a_saved_model_directory_is_an_ordinary_one_not_private(tmp_path):
    import os

    from fr5_rl.deploy.bundle import save_model_dir

    class Saved:
        def save(self, path):
            Path(path).write_text("weights")

    save_model_dir(tmp_path / "final", Saved(), Saved(), {"task": "reach"})
    umask = os.umask(0)
    os.umask(umask)
    assert (tmp_path / "final").stat().st_mode & 0o777 == 0o777 & ~umask


@pytest.mark.parametrize("module", ["train", "evaluate", "imitate", "make_models", "tune", "export_onnx", "compare_run",
                                    "fit_driver"])
def test_help_is_plain_text(module, capsys):
    """--help shows no reStructuredText markup (the docstrings' ``code`` and :class:`roles`)."""
    import importlib

    parser = importlib.import_module(f"fr5_rl.cli.{module}").build_parser()
    text = parser.format_help()
    assert "`" not in text and ":class:" not in text, text


def test_plain_keeps_the_text_of_literals_and_roles():
    from fr5_rl.help_text import plain

    assert plain("``rosrun x`` and :class:`~fr5_rl.envs.FR5Env` or :func:`load` `a`") == "rosrun x and FR5Env or load a"


@pytest.mark.slow  # roslaunch
@pytest.mark.parametrize("arguments, reason", [
    (["model:=/nonexistent"], "no such model directory: /nonexistent"),
    (["model:=models/reach", "robot:=fr10"], "not the fr10"),
])
def test_a_launch_that_cannot_work_stops_at_once_with_its_reason(tmp_path, arguments, reason):
    """Before any node or master starts: the model's arm is read for robot_description."""
    import os
    import subprocess

    env = dict(os.environ, ROS_MASTER_URI="http://127.0.0.1:11598", ROS_LOG_DIR=str(tmp_path))
    result = subprocess.run(["roslaunch", "-p", "11598", "fr5_rl", "sim_policy.launch", "rviz:=false", *arguments],
                            capture_output=True, text=True, timeout=60, env=env, cwd=tmp_path)
    assert result.returncode != 0
    assert reason in result.stdout + result.stderr
    assert "started with pid" not in result.stdout  # nothing was started


def test_gymnasiums_checker_passes_headless(monkeypatch):
    """Without an X display the environment offers no "human" window, so check_env's tour of the
    render modes passes; asking for one still says what to do."""
    import gymnasium as gym
    from gymnasium.utils.env_checker import check_env

    import fr5_rl  # noqa: F401

    monkeypatch.delenv("DISPLAY", raising=False)
    env = gym.make("FR5Reach-v0")
    try:
        check_env(env.unwrapped)
        assert env.unwrapped.metadata["render_modes"] == ["rgb_array"]
    finally:
        env.close()
    with pytest.raises(RuntimeError, match="X display"):
        gym.make("FR5Reach-v0", render_mode="human")


def test_help_shows_each_options_default():
    from fr5_rl.cli.train import build_parser

    text = " ".join(build_parser().format_help().split())
    for option, default in (("--task {reach,grasp,place}", "reach"), ("--algo {ppo,sac,td3,tqc}", "ppo"), ("--seed SEED", "0")):
        assert f"{option} (default: {default})" in text, option
    assert "--resume continue" in text and "(default: False)" not in text  # a switch says nothing of False


def test_the_spec_says_how_long_an_episode_is_configured_to_last():
    import gymnasium as gym

    import fr5_rl  # noqa: F401

    reach = gym.make("FR5Reach-v0")
    longer = gym.make("FR5Grasp-v0", config={"grasp": {"max_steps": 300}})
    try:
        assert reach.spec.max_episode_steps == reach.unwrapped.cfg.reach.max_steps == 150
        assert longer.spec.max_episode_steps == 300  # no TimeLimit at the registered length cuts it short
        reach.reset(seed=0)
        steps, done = 0, False
        while not done:
            _, _, terminated, truncated, _ = reach.step(np.zeros(7, dtype=np.float32))
            steps, done = steps + 1, terminated or truncated
        assert steps == 150 and truncated
    finally:
        reach.close()
        longer.close()
