"""One argument picks the arm everywhere: the environments, the configuration, the model files and
the command lines; a model trained for one arm refuses to run as another."""
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from fr5_rl.config import ConfigError, load_robot_spec, robot_names
from fr5_rl.deploy.bundle import ModelFilesError, arm_of, resolve_model_dir
from fr5_rl.deploy.policy import load_policy
from fr5_rl.env_config import load_env_config
from fr5_rl.envs import FR5Env

REPO = Path(__file__).resolve().parent.parent
FAMILY = ["fr3", "fr5", "fr10", "fr16", "fr20", "fr30"]


def test_the_default_arm_is_the_current_fr5():
    assert load_env_config().robot == "fr5"
    spec = load_robot_spec()
    assert spec.model == "fr5" and spec.flange_frame == "flange" and spec.flange_offset == pytest.approx(0.1)
    assert set(FAMILY) <= set(robot_names())


@pytest.mark.parametrize("robot", FAMILY)
def test_every_arm_builds_its_environment_with_its_cell_and_stays_within_its_rated_speed(robot):
    env = FR5Env("reach", robot=robot)
    try:
        assert env.cfg.robot == robot and env.robot_spec.model == robot
        spec = env.robot_spec
        # The action scaling: a whole step of every joint stays within that joint's rated speed.
        assert env.cfg.action.max_joint_step <= float(spec.velocity_limits.min()) * env.control_dt + 1e-12
        # The cell follows the arm's size: its placement region lies within its reach, in front of it.
        reach = float(-spec.joint_origins_xyz[2][0] - spec.joint_origins_xyz[3][0])
        far = np.hypot(env.cfg.object.region_low[0], max(abs(v) for v in (env.cfg.object.region_low[1],
                                                                           env.cfg.object.region_high[1])))
        assert env.cfg.object.region_high[0] < 0 and far < reach
        obs, _ = env.reset(seed=3)
        for _ in range(5):
            obs, *_ = env.step(env.action_space.sample())
        assert np.all(np.isfinite(obs))
        # The arm in the simulator is the one described: its tcp where the kinematics puts it.
        from fr5_rl.kinematics import ForwardKinematics

        joints = env.episode.joint_states().positions[:6]
        np.testing.assert_allclose(env.tcp_position(), ForwardKinematics(spec).tcp_pose(joints)[0], atol=1e-6)
    finally:
        env.close()


@pytest.mark.parametrize("robot", robot_names())
def test_the_arm_span_is_its_upper_arm_and_forearm_from_the_dh_table(robot):
    """``RobotSpec.arm_span`` (the expert's carry scales with it) against the DH lengths in the
    arm's file, and the cells' sizing rule (each cell is the FR5's scaled by span / 0.82)."""
    from fr5_rl.config import robot_config

    dh = robot_config(robot)["dh"]
    assert load_robot_spec(robot).arm_span == pytest.approx(abs(dh["a2"]) + abs(dh["a3"]))
    width_ratio = load_env_config({"robot": robot}).table.size[1] / load_env_config({"robot": "fr5"}).table.size[1]
    assert width_ratio == pytest.approx(load_robot_spec(robot).arm_span / load_robot_spec("fr5").arm_span, abs=0.01)


def test_a_step_faster_than_the_arms_slowest_joint_is_refused_for_that_arm():
    fr5_cap = float(load_robot_spec("fr5").velocity_limits.min()) * 0.02  # 180 deg/s: 0.0628 rad a step
    load_env_config({"action": {"max_joint_step": fr5_cap}})
    with pytest.raises(ConfigError, match="fr10's slowest rated joint speed"):  # 120 deg/s on j1-j2
        load_env_config({"robot": "fr10", "action": {"max_joint_step": fr5_cap}})


def test_an_unknown_arm_and_a_contradicting_one_are_refused():
    with pytest.raises(ConfigError, match="unknown robot 'fr99'.*fr10"):
        load_env_config({"robot": "fr99"})
    with pytest.raises(ValueError, match="contradicts"):
        FR5Env("reach", config=load_env_config({"robot": "fr10"}), robot="fr5")


def test_a_user_override_of_the_cell_wins_over_the_arms():
    cfg = load_env_config({"robot": "fr10", "object": {"region_low": [-0.9, -0.2]}})
    assert cfg.object.region_low == [-0.9, -0.2]
    assert cfg.object.region_high == load_env_config({"robot": "fr10"}).object.region_high


@pytest.fixture()
def model_for(tmp_path):
    """A copy of the shipped reach model whose meta.json says it was trained for ``robot``."""
    def make(robot: str) -> Path:
        directory = tmp_path / f"reach_{robot}"
        shutil.copytree(REPO / "models" / "reach", directory)
        meta = json.loads((directory / "meta.json").read_text())
        return directory, meta
    return make


def test_a_model_runs_only_as_the_arm_it_was_trained_for(model_for):
    directory, meta = model_for("reach")
    trained_for = meta["robot"]
    other = "fr10" if trained_for != "fr10" else "fr3"
    assert load_policy(directory, "onnx", expected_robot=trained_for).meta["robot"] == trained_for
    with pytest.raises(ModelFilesError, match=f"trained for the {trained_for}, not the {other}"):
        load_policy(directory, "onnx", expected_robot=other)
    assert arm_of(directory, None) == trained_for
    with pytest.raises(ModelFilesError, match=f"not the {other}"):
        arm_of(directory, other)
    # meta.json's arm and the overrides it was trained with must agree: a hand edit is damage.
    meta["robot"] = other
    (directory / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(ModelFilesError, match="damaged"):
        load_policy(directory, "onnx")


def test_evaluate_refuses_another_arm_in_one_line_with_exit_2(capsys, tmp_path):
    from fr5_rl.cli.evaluate import main

    trained_for = json.loads((REPO / "models" / "reach" / "meta.json").read_text())["robot"]
    other = "fr10" if trained_for != "fr10" else "fr3"
    status = main([str(REPO / "models" / "reach"), "--robot", other, "--episodes", "1", "--out",
                   str(tmp_path / "eval.json")])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(err) == 1 and f"not the {other}" in err[0]
    assert not (tmp_path / "eval.json").exists()


def test_a_model_path_is_found_from_the_callers_directory_then_the_package(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert resolve_model_dir("models/reach") == REPO / "models" / "reach"
    (tmp_path / "models" / "reach").mkdir(parents=True)
    assert resolve_model_dir("models/reach") == tmp_path / "models" / "reach"
    with pytest.raises(ModelFilesError, match=f"no such model directory: models/nothing .*{tmp_path}.* and "):
        resolve_model_dir("models/nothing")
