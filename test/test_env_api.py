"""Tests of FR5Env's public API for real-time stand-ins (the ROS simulator node) and of the
rule that only fr5_rl.sim talks to PyBullet.

The simulator's answers are checked against PyBullet queried directly (joints looked up by
name), not against the environment's own helpers.
"""
from __future__ import annotations

import ast
import math
from pathlib import Path
from typing import List

import numpy as np
import pybullet as p
import pytest

from fr5_rl.envs import FR5Env
from fr5_rl.tasks import EpisodeVerdict
from fr5_rl.expert import ScriptedExpert

REPO = Path(__file__).resolve().parent.parent
PACKAGE = REPO / "src" / "fr5_rl"
ARM = [f"j{i}" for i in range(1, 7)]


def pybullet_joint_states(env: FR5Env, names) -> List[tuple]:
    """(position, velocity) of each named joint, straight from PyBullet."""
    robot, client = env.plant.robot.body, env.plant.world.client
    by_name = {p.getJointInfo(robot, i, physicsClientId=client)[1].decode(): i
               for i in range(p.getNumJoints(robot, physicsClientId=client))}
    return [p.getJointState(robot, by_name[name], physicsClientId=client)[:2] for name in names]


# ----------------------------------------------------------------------------- joint_states
@pytest.mark.parametrize("task", ["reach", "grasp"])
def test_joint_states_names_order_and_values(task):
    env = FR5Env(task=task)
    try:
        env.reset(seed=3)
        for _ in range(5):  # moving, so that velocities are not all zero
            env.step(np.array([1.0, -1.0, 0.5, 0.0, 0.0, 0.0, -1.0], dtype=np.float32))
        states = env.episode.joint_states()
        spec = env.robot_spec
        assert list(states.names) == ARM + list(spec.finger_joint_names)
        assert len(spec.finger_joint_names) == 2 and len(states.positions) == len(states.velocities) == 8
        expected = pybullet_joint_states(env, states.names)
        np.testing.assert_array_equal(states.positions, [position for position, _ in expected])
        np.testing.assert_array_equal(states.velocities, [velocity for _, velocity in expected])
        assert np.any(np.abs(states.velocities[:6]) > 1e-3)
        # The fingers together make the opening width the task measures.
        assert sum(states.positions[6:]) == pytest.approx(env.task_state().gripper_width, abs=1e-12)
        np.testing.assert_array_equal(states.positions[:6], env.joint_positions())
    finally:
        env.close()


# ----------------------------------------------------------------------------- advance_physics
def test_physics_dt_is_the_configured_step():
    for task, physics_dt in (("reach", 0.01), ("grasp", 0.005)):
        env = FR5Env(task=task)
        try:
            assert env.episode.physics_dt == physics_dt
        finally:
            env.close()
    env = FR5Env(task="reach", config={"reach": {"simulation": {"physics_dt": 0.005}}})
    try:
        assert env.episode.physics_dt == 0.005
    finally:
        env.close()


def test_advance_physics_tracks_arm_target_and_gripper_width():
    env = FR5Env(task="grasp")
    try:
        env.reset(seed=1)
        spec = env.robot_spec
        start = env.joint_positions()
        target = start + np.array([0.3, -0.2, 0.2, 0.0, 0.0, 0.25])
        states = pybullet_joint_states(env, spec.finger_joint_names)
        open_width = sum(position for position, _ in states)
        assert open_width == pytest.approx(spec.max_opening_width, abs=1e-3)
        errors = []
        for _ in range(200):  # 1 s of simulated time at 5 ms
            env.episode.advance_physics(target, 0.0)
            errors.append(float(np.max(np.abs(np.array([q for q, _ in pybullet_joint_states(env, ARM)]) - target))))
        assert errors[0] < 0.3 + 1e-9  # one physics step moved it, a little
        assert errors[-1] < 0.01, errors[-1]
        assert errors[49] < errors[0]
        closed = sum(position for position, _ in pybullet_joint_states(env, spec.finger_joint_names))
        assert closed < 0.1 * open_width  # nothing in between: the fingers closed
        assert env.episode.gripper_command_width == 0.0
    finally:
        env.close()


def test_advance_physics_one_step_is_physics_dt():
    """A joint commanded to move advances by about velocity * physics_dt per call, not per control period."""
    env = FR5Env(task="reach")
    try:
        env.reset(seed=2)
        start = env.joint_positions()
        env.episode.advance_physics(start + np.array([1.0, 0, 0, 0, 0, 0]), env.robot_spec.max_opening_width)
        moved = abs(env.joint_positions()[0] - start[0])
        # Capped at the joint's velocity limit for one physics step (plus solver slack).
        assert 0.0 < moved <= env.robot_spec.velocity_limits[0] * env.episode.physics_dt * 1.05
    finally:
        env.close()


# ----------------------------------------------------------------------------- judge_period
def test_judge_period_times_out_at_max_steps():
    env = FR5Env(task="reach", config={"reach": {"max_steps": 6}})
    try:
        env.reset(seed=0)
        hold = env.joint_positions()
        verdicts = []
        for _ in range(6):
            for _ in range(int(round(env.control_dt / env.episode.physics_dt))):
                env.episode.advance_physics(hold, env.robot_spec.max_opening_width)
            verdicts.append(env.episode.judge_period())
        assert all(isinstance(v, EpisodeVerdict) for v in verdicts)
        assert [v.steps for v in verdicts] == [1, 2, 3, 4, 5, 6]
        assert not any(v.ended or v.success or v.failure for v in verdicts[:-1])
        last = verdicts[-1]
        assert last.truncated and not last.terminated and last.ended
        assert last.failure == "timeout" and last.outcome.failure is None and not last.success
        assert set(last.terms) == {"approach", "orientation", "gripper"}
        env.reset(seed=0)  # the count starts over
        assert env.episode.judge_period().steps == 1
    finally:
        env.close()


def test_step_times_out_with_the_same_verdict():
    env = FR5Env(task="grasp", config={"grasp": {"max_steps": 4}})
    try:
        env.reset(seed=0)
        results = [env.step(np.zeros(7, dtype=np.float32)) for _ in range(4)]
        assert [r[3] for r in results] == [False, False, False, True]
        assert not any(r[2] for r in results)
        assert results[-1][4]["failure"] == "timeout" and results[-1][4]["is_success"] is False
    finally:
        env.close()


def record_arm_commands(env: FR5Env) -> list:
    """Every (arm targets, opening width) the environment sends to the robot."""
    plant, original, commands = env.plant, env.plant.command, []

    def command(joint_targets, opening_width, period=None):
        commands.append((list(joint_targets), opening_width))
        original(joint_targets, opening_width, period)

    plant.command = command
    return commands


@pytest.mark.parametrize("actor", ["expert", "random"])
def test_judge_period_gives_the_verdicts_step_gives(actor):
    """Replaying step()'s commands through advance_physics + judge_period gives the same verdict,
    step by step: success, failure, terminated, truncated, the count, the shaping terms.

    Reach with the gripper kept open, where the finger ramp per physics step and per control
    step agree, so that both runs are the same physics."""
    config = {"reach": {"max_steps": 60}}
    stepped, replayed = FR5Env(task="reach", config=config), FR5Env(task="reach", config=config)
    try:
        seed = 4
        obs, _ = stepped.reset(seed=seed)
        commands = record_arm_commands(stepped)
        expert, rng = ScriptedExpert(stepped), np.random.default_rng(seed)
        results = []
        while True:
            action = expert.act(obs) if actor == "expert" else rng.uniform(-0.3, 0.3, 7).astype(np.float32)
            action[6] = 1.0  # open
            obs, _, terminated, truncated, info = stepped.step(action)
            results.append((terminated, truncated, info))
            if terminated or truncated:
                break
        assert len(commands) == len(results)
        if actor == "expert":
            assert results[-1][2]["is_success"]
        else:
            assert results[-1][2]["failure"] in ("collision", "timeout")

        replayed.reset(seed=seed)
        substeps = int(round(replayed.control_dt / replayed.episode.physics_dt))
        for step, ((targets, width), (terminated, truncated, info)) in enumerate(zip(commands, results), 1):
            for _ in range(substeps):
                replayed.episode.advance_physics(targets, width)
            verdict = replayed.episode.judge_period()
            assert (verdict.success, verdict.failure, verdict.terminated, verdict.truncated, verdict.steps) == \
                (info["is_success"], info["failure"], terminated, truncated, step)
            assert {f"term_{name}": value for name, value in verdict.terms.items()} == \
                {key: value for key, value in info.items() if key.startswith("term_")}
    finally:
        stepped.close()
        replayed.close()


# ----------------------------------------------------------------------------- object and scene
def test_advance_period_reproduces_step_exactly():
    """Lockstep's contract: step()'s arm targets and widths, replayed through advance_period +
    judge_period in a second env, give bit-identical joint states and the same verdicts, period
    by period; grasp, with the gripper closing and the object lifted."""
    stepped, replayed = FR5Env(task="grasp"), FR5Env(task="grasp")
    try:
        seed = 3
        obs, _ = stepped.reset(seed=seed)
        commands = record_arm_commands(stepped)
        expert = ScriptedExpert(stepped)
        expert.reset()
        states, verdicts = [], []
        while True:
            obs, _, terminated, truncated, info = stepped.step(expert.act(obs))
            states.append(stepped.episode.joint_states())
            verdicts.append((info["is_success"], info["failure"], terminated, truncated))
            if terminated or truncated:
                break
        assert verdicts[-1][0], "the expert should lift the object"
        assert min(width for _, width in commands) < 0.05  # the gripper did close

        replayed.reset(seed=seed)
        for (targets, width), state, expected in zip(commands, states, verdicts):
            replayed.episode.advance_period(targets, width)
            verdict = replayed.episode.judge_period()
            assert replayed.episode.joint_states() == state
            assert (verdict.success, verdict.failure, verdict.terminated, verdict.truncated) == expected
    finally:
        stepped.close()
        replayed.close()


def test_object_pose_is_the_simulators():
    env = FR5Env(task="grasp")
    try:
        env.reset(seed=5, options={"object_xy": [-0.5, 0.1]})
        pose = env.episode.object_pose()
        assert pose.frame_id == "base_link"
        position, quaternion = p.getBasePositionAndOrientation(env.plant.world.object_id, physicsClientId=env.plant.world.client)
        assert pose.position == tuple(position) and pose.quaternion == tuple(quaternion)
        assert pose.position[:2] == pytest.approx((-0.5, 0.1))
        assert pose.position[2] == pytest.approx(env.object_rest_z)
        assert math.isclose(sum(v * v for v in pose.quaternion), 1.0, abs_tol=1e-9)
    finally:
        env.close()


def test_scene_describes_table_and_object_as_placed():
    env = FR5Env(task="reach", config={"object": {"shape": "box"}})
    try:
        env.reset(seed=0)
        scene = env.episode.scene()
        cfg = env.cfg
        assert scene.frame_id == "base_link"
        assert scene.table_size == tuple(cfg.table.size)
        assert scene.table_center == (-0.55, 0.0, cfg.table.top_height - cfg.table.size[2] / 2.0)
        assert scene.table_top_height == cfg.table.top_height
        assert scene.object_shape == "box" and scene.object_dims == (cfg.object.half_extent,)
        assert scene.object_size == (0.045, 0.045, 0.045)
        assert scene.object_rest_z == env.object_rest_z == pytest.approx(0.0225)
    finally:
        env.close()
    env = FR5Env(task="grasp", config={"randomisation": {"enabled": True, "object_size_scale": [1.5, 1.5]}})
    try:
        env.reset(seed=0)
        scene = env.episode.scene()
        assert scene.object_shape == "cylinder"
        assert scene.object_dims == pytest.approx((0.025 * 1.5, 0.06 * 1.5))  # as placed, not nominal
        assert scene.object_size == pytest.approx((0.075, 0.075, 0.09))
        # The simulator's object has that size: its collision box spans the scene's height.
        low, high = p.getAABB(env.plant.world.object_id, physicsClientId=env.plant.world.client)
        assert high[2] - low[2] == pytest.approx(0.09, abs=2e-3)
    finally:
        env.close()


def test_reset_takes_the_rest_height_from_env_config_object_rest_z(monkeypatch):
    """_apply_randomisation gets the rest height from EnvConfig.object_rest_z: a spy that
    shifts its answer by 1 mm shows up in the placement, the observation's reference and the scene."""
    from fr5_rl.env_config import EnvConfig

    calls = []
    object_rest_z = EnvConfig.object_rest_z

    def spy(cfg, size_scale=1.0):
        calls.append((cfg, size_scale))
        return object_rest_z(cfg, size_scale) + 0.001

    env = FR5Env(task="grasp", config={"randomisation": {"enabled": True}})
    monkeypatch.setattr(EnvConfig, "object_rest_z", spy)
    try:
        _, info = env.reset(seed=7)
        assert len(calls) == 1 and calls[0][0] is env.cfg
        size = calls[0][1]
        assert 0.8 <= size <= 1.2 and size != 1.0
        expected = object_rest_z(env.cfg, size) + 0.001
        assert env.object_rest_z == expected == env.episode.scene().object_rest_z
        assert info["object_start"][2] == expected
        assert env.episode.object_pose().position[2] == pytest.approx(expected, abs=1e-12)
        # and the nominal half height scaled by the drawn size, on the table
        assert object_rest_z(env.cfg, size) == pytest.approx(0.03 * size)
        assert env.episode.scene().object_dims[1] == pytest.approx(0.06 * size)
    finally:
        env.close()


# ----------------------------------------------------------------------------- pybullet stays in sim/
def pybullet_imports(root: Path) -> List[str]:
    """``file:line`` of every import of pybullet (or pybullet_data, pybullet_utils, ...) under
    ``root`` outside its ``sim/`` folder: import statements and importlib/__import__ calls."""
    found = []
    for path in sorted(root.rglob("*.py")):
        relative = path.relative_to(root)
        if relative.parts[0] == "sim":
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
            modules = []
            if isinstance(node, ast.Import):
                modules = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                modules = [node.module or ""]
            elif isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant):
                name = node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", "")
                if name in ("import_module", "__import__"):
                    modules = [str(node.args[0].value)]
            if any(module.split(".")[0].startswith("pybullet") for module in modules):
                found.append(f"{relative}:{node.lineno}")
    return found


def test_only_sim_imports_pybullet():
    assert (PACKAGE / "sim" / "world.py").is_file()
    assert pybullet_imports(PACKAGE) == []
    # ...and sim/ does, once (sim/bullet.py, which drops its banner): the check looks where it is.
    assert "import pybullet" in (PACKAGE / "sim" / "bullet.py").read_text(encoding="utf-8")
    assert "from .bullet import p" in (PACKAGE / "sim" / "robot.py").read_text(encoding="utf-8")


def test_pybullet_import_check_finds_imports(tmp_path):
    (tmp_path / "sim").mkdir()
    (tmp_path / "sim" / "ok.py").write_text("import pybullet as p\n")
    (tmp_path / "ros").mkdir()
    (tmp_path / "ros" / "a.py").write_text("import numpy\n\ndef f():\n    import pybullet as p\n")
    (tmp_path / "b.py").write_text("from pybullet_utils import bullet_client\n")
    (tmp_path / "c.py").write_text("import importlib\nimportlib.import_module('pybullet')\n")
    (tmp_path / "d.py").write_text("x = 'pybullet is not imported here'\n")
    assert pybullet_imports(tmp_path) == ["b.py:1", "c.py:2", "ros/a.py:4"]


def episode_internals_used(path: Path) -> List[str]:
    """``line: expression`` of every attribute the file reads off a ``sim`` (``sim.x`` or
    ``self.sim.x``, an :class:`~fr5_rl.episode.Episode`) below its API: the plant's PyBullet
    world or robot, the task or chain's insides, or a private name."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if not isinstance(node, ast.Attribute):
            continue
        owner = node.value
        is_sim = (isinstance(owner, ast.Name) and owner.id == "sim") or \
            (isinstance(owner, ast.Attribute) and owner.attr == "sim")
        if is_sim and (node.attr in ("plant", "chain", "task", "cfg") or node.attr.startswith("_")):
            found.append((node.lineno, f"{node.lineno}: {ast.unparse(node)}"))
    return [text for _, text in sorted(found)]


@pytest.mark.parametrize("stand_in", ["ros/sim_node.py", "ros/sim_loops.py", "chain_emulation.py",
                                      "sim_to_real/replay.py"])
def test_the_stand_ins_use_only_the_episodes_api(stand_in):
    assert episode_internals_used(PACKAGE / stand_in) == []


def test_the_api_check_finds_what_reaches_below_it(tmp_path):
    probe = tmp_path / "probe.py"
    probe.write_text("sim.plant.world.client\nself.sim.task.judge\nself.sim.scene()\nsim._steps\n")
    assert episode_internals_used(probe) == ["1: sim.plant", "2: self.sim.task", "4: sim._steps"]


def timing_env(delay, age):
    """Reach at 5 ms physics steps (4 per period) with fixed real-time timing, nothing else random."""
    return FR5Env(task="reach", config={"reach": {"simulation": {"physics_dt": 0.005}}, "randomisation": {
        "enabled": True, "object_size_scale": [1, 1], "object_mass_scale": [1, 1], "friction_scale": [1, 1],
        "joint_damping": [0, 0], "command_delay_s": [delay, delay], "observation_age_s": [age, age]}})


def test_command_delay_keeps_the_previous_command_standing():
    """With a 10 ms delay the first two of four physics steps track the previous period's
    targets (at the first step: the reset pose), then the new ones."""
    env = timing_env(0.01, 0.0)
    try:
        env.reset(seed=1)
        start = list(env.joint_positions())
        commands = record_arm_commands(env)
        action = np.array([0.5, -0.5, 0.5, 0, 0, 0, 1], dtype=np.float32)
        env.step(action)
        env.step(action)
        assert len(commands) == 4  # two per period: the standing command, then the new one
        np.testing.assert_allclose(commands[0][0], start)
        assert not np.allclose(commands[1][0], start)
        np.testing.assert_allclose(commands[2][0], commands[1][0])  # period 1's command stands into period 2
    finally:
        env.close()


def test_observation_age_observes_an_earlier_joint_state():
    """A 10 ms observation age: the observation (and the shaper's base) is the robot measured
    two physics steps before the period ends, not the state at its end."""
    aged, fresh = timing_env(0.0, 0.01), timing_env(0.0, 0.0)
    try:
        action = np.array([0.8, -0.8, 0.8, 0, 0, 0, 1], dtype=np.float32)
        for env in (aged, fresh):
            env.reset(seed=2)
        measured = []
        original = aged.plant.measure
        aged.plant.measure = lambda: measured.append(original()) or measured[-1]
        obs_aged = aged.step(action)[0]
        obs_fresh = fresh.step(action)[0]
        np.testing.assert_array_equal(aged.joint_positions(), fresh.joint_positions())  # same physics
        early = measured[0][0]  # the first measurement of the step: taken two steps early
        assert not np.allclose(early, aged.joint_positions())
        np.testing.assert_allclose(aged.episode.chain.observed_joint_positions, early)
        assert not np.allclose(obs_aged[:6], obs_fresh[:6])
    finally:
        aged.close()
        fresh.close()
