"""Tests of the gymnasium environments FR5Reach-v0 and FR5Grasp-v0 (fr5_rl.envs).

Where a property could be checked through the environment's own helpers, it is checked
independently instead: the tcp pose and contacts come straight from PyBullet (link found by
name), the joint targets are intercepted at the robot's command call and compared with the
joint state PyBullet reports at that moment, and the FR5 limits are written out literally
from the published robot data (the same numbers as test_description.py).
"""
from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pybullet as p
import pytest
from gymnasium.utils.env_checker import check_env, env_render_passive_checker

import fr5_rl  # noqa: F401  (registers the environments)
from fr5_rl.config import ConfigError, load_robot_spec
from fr5_rl.envs import FR5Env
from fr5_rl.expert import ScriptedExpert
from fr5_rl.kinematics import ForwardKinematics

REPO = Path(__file__).resolve().parent.parent
ENV_IDS = ["FR5Reach-v0", "FR5Grasp-v0"]
TASKS = ["reach", "grasp"]

# FAIRINO FR5 joint limits (rad) and velocity limits (rad/s), j1..j6, from the published data.
# The current FR5's datasheet: j3's soft limit +-160 deg, 180 deg/s on every axis.
FR5_LOWER = np.array([-3.0543, -4.6251, -2.7925, -4.6251, -3.0543, -3.0543])
FR5_UPPER = np.array([3.0543, 1.4835, 2.7925, 1.4835, 3.0543, 3.0543])
FR5_VELOCITY = np.full(6, 3.1416)
CONTROL_DT = 0.02
FAR_CORNER = [-0.36, 0.29]  # object placement well away from the arm's path to the table


# ----------------------------------------------------------------------------- helpers
def make(task: str, **config) -> FR5Env:
    return FR5Env(task=task, config=config or None)


def joint_indices(env: FR5Env, names) -> list:
    """PyBullet joint indices looked up by name (independent of FR5Robot's maps)."""
    robot, client = env.plant.robot.body, env.plant.world.client
    by_name = {p.getJointInfo(robot, i, physicsClientId=client)[1].decode(): i
               for i in range(p.getNumJoints(robot, physicsClientId=client))}
    return [by_name[n] for n in names]


def tcp_link_index(env: FR5Env) -> int:
    robot, client = env.plant.robot.body, env.plant.world.client
    for i in range(p.getNumJoints(robot, physicsClientId=client)):
        if p.getJointInfo(robot, i, physicsClientId=client)[12].decode() == "tcp":
            return i
    raise AssertionError("the robot has no 'tcp' link")


def tcp_pose_pybullet(env: FR5Env):
    state = p.getLinkState(env.plant.robot.body, tcp_link_index(env), computeForwardKinematics=1,
                           physicsClientId=env.plant.world.client)
    return np.array(state[4]), np.array(p.getMatrixFromQuaternion(state[5])).reshape(3, 3)


def measured_arm_positions(env: FR5Env) -> np.ndarray:
    states = p.getJointStates(env.plant.robot.body, joint_indices(env, [f"j{i}" for i in range(1, 7)]),
                              physicsClientId=env.plant.world.client)
    return np.array([s[0] for s in states])


def record_commands(env: FR5Env) -> list:
    """Intercept every arm command: (targets, arm position PyBullet reports at that moment)."""
    plant = env.plant
    original = plant.command
    records = []

    def command(joint_targets, opening_width, period=None):
        records.append((np.array(joint_targets, dtype=np.float64), measured_arm_positions(env)))
        original(joint_targets, opening_width, period=period)

    plant.command = command
    return records


def rollout(env: FR5Env, seed: int, actions) -> tuple:
    obs, _ = env.reset(seed=seed)
    observations, rewards = [obs.copy()], []
    for action in actions:
        obs, reward, terminated, truncated, _ = env.step(action)
        observations.append(obs.copy())
        rewards.append(reward)
        if terminated or truncated:
            break
    return np.array(observations), np.array(rewards)


def run_expert(env: FR5Env, seed: int, on_step=None) -> dict:
    expert = ScriptedExpert(env)
    obs, _ = env.reset(seed=seed)
    expert.reset()
    while True:
        obs, reward, terminated, truncated, info = env.step(expert.act(obs))
        if on_step is not None:
            on_step(reward, info)
        if terminated or truncated:
            return info


# ----------------------------------------------------------------------------- API
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_check_env(env_id):
    env = gym.make(env_id)
    try:
        # The render check makes every declared render mode; "human" opens the PyBullet GUI,
        # which ends the process when there is no X display. It runs under Xvfb below.
        check_env(env.unwrapped, skip_render_check=True)
    finally:
        env.close()


@pytest.mark.slow  # a GUI client under Xvfb
@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="xvfb-run is not installed")
def test_check_env_with_render_modes_under_xvfb():
    """check_env including its render check (rgb_array and the GUI "human" mode)."""
    code = ("import gymnasium as gym, fr5_rl\n"
            "from gymnasium.utils.env_checker import check_env\n"
            "for env_id in ('FR5Reach-v0', 'FR5Grasp-v0'):\n"
            "    env = gym.make(env_id)\n"
            "    check_env(env.unwrapped)\n"
            "    env.close()\n"
            "print('check_env passed')\n")
    env = dict(os.environ)
    env["PYTHONPATH"] = f"{REPO / 'src'}{os.pathsep}{env.get('PYTHONPATH', '')}"
    result = subprocess.run(["xvfb-run", "-a", sys.executable, "-c", code], cwd=REPO, env=env,
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0 and "check_env passed" in result.stdout, result.stderr[-3000:]


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_rgb_array_render(env_id):
    env = gym.make(env_id, render_mode="rgb_array")
    try:
        env.reset(seed=0)
        env_render_passive_checker(env.unwrapped)
        frame = env.render()
        assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
        assert frame.std() > 0  # not a blank image
    finally:
        env.close()


def test_render_beside_envs_without_renderer():
    """Envs built without a render mode drop PyBullet's renderer from their own client only: a
    rendering env in the same process still draws the object (red pixels where the object is
    dropped from the non-rendering world's meshes, it would be missing)."""
    quiet_before = FR5Env(task="reach")
    drawing = FR5Env(task="reach", render_mode="rgb_array")
    quiet_after = FR5Env(task="reach")
    try:
        for env in (quiet_before, drawing, quiet_after):
            env.reset(seed=0)
        frame = drawing.render().astype(int)
        red = (frame[:, :, 0] > 150) & (frame[:, :, 1] < 90) & (frame[:, :, 2] < 90)
        assert red.sum() > 20, "the object is not in the picture"
        assert quiet_before.render() is None
        with pytest.raises(RuntimeError, match="render_mode='rgb_array'"):
            quiet_after.plant.world.render()
    finally:
        for env in (quiet_before, drawing, quiet_after):
            env.close()


@pytest.mark.parametrize("env_id,size", [("FR5Reach-v0", 23), ("FR5Grasp-v0", 24)])
def test_spaces_and_control_dt(env_id, size):
    env = gym.make(env_id)
    try:
        assert env.unwrapped.control_dt == 0.02
        assert env.unwrapped.plant.world.substeps * env.unwrapped.plant.world.physics_dt == pytest.approx(0.02)
        assert env.observation_space.shape == (size,)
        assert env.action_space.shape == (7,)
        np.testing.assert_array_equal(env.action_space.low, -1.0)
        np.testing.assert_array_equal(env.action_space.high, 1.0)
    finally:
        env.close()


def test_robot_spec_matches_published_fr5_limits():
    spec = load_robot_spec()
    np.testing.assert_allclose(spec.lower_limits, FR5_LOWER, atol=1e-9)
    np.testing.assert_allclose(spec.upper_limits, FR5_UPPER, atol=1e-9)
    np.testing.assert_allclose(spec.velocity_limits, FR5_VELOCITY, atol=1e-9)


# ----------------------------------------------------------------------------- determinism
@pytest.mark.parametrize("task", TASKS)
def test_same_seed_same_rollout(task):
    """reset(seed=s) reproduces the reset observation and a 30-step rollout bit for bit, on a
    fresh environment and after other episodes have run in it."""
    env = make(task)
    try:
        actions = np.random.default_rng(42).uniform(-1, 1, (30, 7)).astype(np.float32)
        actions[:, 6] = 1.0
        first = rollout(env, 3, actions)
        second = rollout(env, 3, actions)
        rollout(env, 8, np.ones((20, 7)))  # something else in between
        third = rollout(env, 3, actions)
        assert len(first[1]) == 30, "the reference rollout should not end early"
        for other in (second, third):
            np.testing.assert_array_equal(first[0][0], other[0][0])  # reset observation
            np.testing.assert_array_equal(first[0], other[0])
            np.testing.assert_array_equal(first[1], other[1])
        fresh = rollout(make(task), 3, actions)
        np.testing.assert_array_equal(first[0], fresh[0])
        np.testing.assert_array_equal(first[1], fresh[1])
    finally:
        env.close()


def expert_rollout(env: FR5Env, seed: int, max_steps: int = 400) -> np.ndarray:
    """Observations of one scripted-expert episode (it touches, grips and lifts the object)."""
    expert = ScriptedExpert(env)
    obs, _ = env.reset(seed=seed)
    observations = [obs.copy()]
    for _ in range(max_steps):
        obs, _, terminated, truncated, _ = env.step(expert.act(obs))
        observations.append(obs.copy())
        if terminated or truncated:
            break
    return np.array(observations)


@pytest.mark.parametrize("task", TASKS)
def test_same_seed_same_rollout_with_object_contact(task):
    """Nothing of an episode may carry over into the next through the simulator: contact
    points still valid where the object is placed again, or sleep state. The same seed right
    after a short episode on the same placement, after itself and after a different episode
    reproduces a fresh environment's expert rollout bit for bit."""
    reference = expert_rollout(make(task), 5)
    env = make(task)
    try:
        expert_rollout(env, 5, max_steps=3)  # the object settles where the next reset puts it again
        for label in ("after a short episode on the same placement", "after itself"):
            np.testing.assert_array_equal(expert_rollout(env, 5), reference, err_msg=label)
        expert_rollout(env, 6)
        np.testing.assert_array_equal(expert_rollout(env, 5), reference, err_msg="after another episode")
    finally:
        env.close()


@pytest.mark.parametrize("task", TASKS)
def test_different_seeds_different_placements(task):
    env = make(task)
    try:
        cfg = env.cfg.object
        low, high = np.array(cfg.region_low), np.array(cfg.region_high)
        placements = []
        for seed in range(8):
            _, info = env.reset(seed=seed)
            position = env.object_position()
            np.testing.assert_allclose(position, info["object_start"], atol=1e-9)
            assert np.all(position[:2] >= low) and np.all(position[:2] <= high)
            placements.append(position[:2])
        placements = np.array(placements)
        distances = np.linalg.norm(placements[:, None] - placements[None], axis=-1)
        assert distances[~np.eye(len(placements), dtype=bool)].min() > 1e-3
        # and the start configuration is randomised too
        env.reset(seed=0)
        q0 = measured_arm_positions(env)
        env.reset(seed=1)
        assert np.abs(measured_arm_positions(env) - q0).max() > 1e-3
    finally:
        env.close()


# ----------------------------------------------------------------------------- the object at rest
@pytest.mark.parametrize("task", TASKS)
def test_an_untouched_object_rests_asleep_after_its_first_physics_step(task):
    """The object settles in the first physics step after its placement, then does not move
    while nothing touches it: awake, it wobbled by up to ~0.2 mm over an episode and cost a
    quarter to a third of every physics step."""
    env = make(task)
    try:
        for seed in range(4):
            env.reset(seed=seed)
            placed = env.episode.object_pose()
            env.step(np.zeros(7, dtype=np.float32))
            settled = env.episode.object_pose()
            assert settled != placed  # the first step settles it onto the table
            for _ in range(40):  # the arm holds its start, clear of the object
                env.step(np.zeros(7, dtype=np.float32))
            assert env.episode.object_pose() == settled, seed
    finally:
        env.close()


def test_a_sleeping_object_wakes_when_the_fingers_touch_it():
    """Asleep on the table, the object still moves when pushed: the expert grasps and lifts it."""
    env = make("grasp")
    try:
        info = run_expert(env, 4)
        assert info["is_success"], info
        assert env.object_position()[2] > env.object_rest_z + env.cfg.grasp.lift_height - 0.005
    finally:
        env.close()


# ----------------------------------------------------------------------------- expert / success
def test_scripted_expert_reach_success_is_real():
    env = make("reach")
    try:
        cfg = env.cfg.reach
        assert cfg.success_distance <= 0.015 and cfg.max_approach_angle_deg <= 15.0
        finger_joints = joint_indices(env, env.robot_spec.finger_joint_names)
        successes = 0
        for seed in range(10):
            info = run_expert(env, seed)
            if not info["is_success"]:
                continue
            successes += 1
            assert info["failure"] is None
            tcp, rotation = tcp_pose_pybullet(env)
            obj = np.array(p.getBasePositionAndOrientation(env.plant.world.object_id,
                                                           physicsClientId=env.plant.world.client)[0])
            assert np.linalg.norm(env.tcp_position() - env.object_position()) <= 0.015
            assert np.linalg.norm(tcp - obj) <= 0.015, seed
            angle = math.degrees(math.acos(np.clip(-rotation[2, 2], -1.0, 1.0)))
            assert angle <= 15.0, (seed, angle)
            width = sum(p.getJointState(env.plant.robot.body, j, physicsClientId=env.plant.world.client)[0]
                        for j in finger_joints)
            assert width >= cfg.min_open_width
            # no robot link other than the finger pads touches anything
            for contact in p.getContactPoints(bodyA=env.plant.robot.body, physicsClientId=env.plant.world.client):
                assert contact[2] == env.plant.world.object_id and contact[3] in finger_joints, contact
        assert successes >= 9, f"scripted expert solved reach on only {successes}/10 seeds"
    finally:
        env.close()


def test_reach_success_needs_pointing_down():
    """The same tcp position with the gripper tilted 90 degrees is not a success."""
    env = make("reach")
    try:
        info = run_expert(env, 0)
        assert info["is_success"]
        state = env.task_state()
        judged = env.task.judge(state, env.control_dt)
        assert judged.success
        state.tcp_approach_axis = (0.0, 0.0, 1.0)  # tcp z axis pointing straight up
        assert not env.task.judge(state, env.control_dt).success
        state.tcp_approach_axis = (1.0, 0.0, 0.0)  # horizontal
        assert not env.task.judge(state, env.control_dt).success
    finally:
        env.close()


# ----------------------------------------------------------------------------- collisions
@pytest.mark.parametrize("task", TASKS)
@pytest.mark.parametrize("joints", [(1,), (1, 2)], ids=["j2", "j2+j3"])
def test_driving_into_table_is_a_collision(task, joints):
    """j2 (+ j3) forward: the arm folds down onto the table. (j3 alone stops at its joint limit
    with the gripper hovering above the base, so it is not used.)"""
    env = make(task)
    try:
        env.reset(seed=0, options={"object_xy": FAR_CORNER})
        action = np.zeros(7, dtype=np.float32)
        action[list(joints)] = 1.0
        action[6] = 1.0
        robot, table, client = env.plant.robot.body, env.plant.world.table_id, env.plant.world.client
        start_height = tcp_pose_pybullet(env)[0][2]
        for step in range(150):
            _, reward, terminated, truncated, info = env.step(action)
            touching_table = len(p.getContactPoints(bodyA=robot, bodyB=table, physicsClientId=client)) > 0
            # The episode ends exactly at the first step with a robot-table contact.
            assert terminated == touching_table, (step, info)
            if terminated:
                break
        assert terminated and not truncated
        assert info["failure"] == "collision"
        assert info["is_success"] is False
        assert info["reward_collision"] == -env.cfg.reward.collision_penalty < 0
        assert reward < 0
        assert tcp_pose_pybullet(env)[0][2] < start_height - 0.1  # it really went down
        assert not p.getContactPoints(bodyA=robot, bodyB=env.plant.world.object_id, physicsClientId=client)
    finally:
        env.close()


def test_every_link_of_the_robot_meets_other_bodies():
    """The robot's links are kept out of each other's broadphase pairs (their own collision
    group); that must leave every link with a collision shape, the base included, colliding with
    a body of Bullet's default group (a dynamic ball dropped into the link), and every link but
    the static base with a static body (a box like the table). The base and the first link stand
    on the table without touching it."""
    env = make("grasp")
    try:
        env.reset(seed=0, options={"object_xy": FAR_CORNER})
        client, robot = env.plant.world.client, env.plant.robot.body
        links = [link for link in range(-1, p.getNumJoints(robot, physicsClientId=client))
                 if p.getCollisionShapeData(robot, link, physicsClientId=client)]
        assert len(links) >= 9  # the base, six arm links, the gripper's body and fingers
        for link in links:
            low, high = p.getAABB(robot, link, physicsClientId=client)
            centre = [(a + b) / 2.0 for a, b in zip(low, high)]
            size = max(b - a for a, b in zip(low, high))
            ball = p.createMultiBody(0.1, p.createCollisionShape(p.GEOM_SPHERE, radius=size, physicsClientId=client),
                                     -1, centre, physicsClientId=client)
            box = p.createMultiBody(0.0, p.createCollisionShape(p.GEOM_BOX, halfExtents=[size] * 3,
                                                                physicsClientId=client),
                                    -1, centre, physicsClientId=client)
            p.performCollisionDetection(physicsClientId=client)
            assert p.getContactPoints(bodyA=robot, bodyB=ball, linkIndexA=link, physicsClientId=client), link
            touches_box = bool(p.getContactPoints(bodyA=robot, bodyB=box, linkIndexA=link, physicsClientId=client))
            assert touches_box == (link >= 0), link  # the base is static as the box is: never paired
            p.removeBody(ball, physicsClientId=client)
            p.removeBody(box, physicsClientId=client)
        table_contacts = p.getContactPoints(bodyA=robot, bodyB=env.plant.world.table_id, physicsClientId=client)
        assert not table_contacts  # standing on it is not touching it
    finally:
        env.close()


def test_every_joint_is_capped_at_the_fastest_rated_joint_speed():
    """PyBullet keeps one speed cap per body: it must be the fastest arm joint's rated speed on
    every joint. Driven far beyond it, no joint goes faster, and the arm reaches it (a cap set
    per joint with the fingers last held the whole arm at the fingers' 0.08 m/s)."""
    env = make("reach")
    try:
        env.reset(seed=0, options={"object_xy": FAR_CORNER})
        client, robot = env.plant.world.client, env.plant.robot.body
        cap = float(max(env.robot_spec.velocity_limits))
        joints = env.plant.robot.all_joints
        p.setJointMotorControlArray(robot, joints, p.VELOCITY_CONTROL, targetVelocities=[10.0] * len(joints),
                                    forces=[1e4] * len(joints), physicsClientId=client)
        fastest = 0.0
        for _ in range(5):
            p.stepSimulation(physicsClientId=client)
            speeds = [abs(state[1]) for state in p.getJointStates(robot, joints, physicsClientId=client)]
            assert max(speeds) <= cap + 1e-9, speeds
            fastest = max(fastest, max(speeds[:len(env.plant.robot.arm_joints)]))
        assert fastest == pytest.approx(cap, abs=1e-6)
    finally:
        env.close()


def test_scripted_downward_motion_into_table_is_a_collision():
    """Straight down under IK, gripper pointing down, until something touches the table."""
    env = make("reach")
    try:
        env.reset(seed=1, options={"object_xy": FAR_CORNER})
        expert = ScriptedExpert(env)
        max_step = env.cfg.action.max_joint_step
        for _step in range(200):
            q = env.joint_positions()
            tcp, _ = env.kinematics.tcp_pose(q)
            q_target = expert._inverse_kinematics(tcp + np.array([0.0, 0.0, -0.02]), q)
            delta = (q_target - q) / max_step
            action = np.append(delta / max(1.0, np.abs(delta).max()), 1.0)
            _, _, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                break
        assert terminated and info["failure"] == "collision" and not info["is_success"]
        assert p.getContactPoints(bodyA=env.plant.robot.body, bodyB=env.plant.world.table_id,
                                  physicsClientId=env.plant.world.client)
    finally:
        env.close()


# ----------------------------------------------------------------------------- joint targets
def check_targets(records, limit_slack=0.0):
    step_limit = FR5_VELOCITY * CONTROL_DT
    worst = 0.0
    for targets, measured in records:
        assert np.all(np.isfinite(targets))
        assert np.all(targets >= FR5_LOWER) and np.all(targets <= FR5_UPPER), targets
        excess = np.abs(targets - measured) - step_limit
        worst = max(worst, float(excess.max()))
    assert worst <= 1e-9, f"a target was {worst:.2e} rad beyond velocity_limit * control_dt"


@pytest.mark.parametrize("task", TASKS)
@pytest.mark.parametrize("scale", [1.0, 10.0])
def test_joint_targets_stay_safe_under_random_actions(task, scale):
    env = make(task)
    try:
        records = record_commands(env)
        rng = np.random.default_rng(7)
        env.reset(seed=0)
        episodes = 0
        for step in range(1500):
            if step % 3 == 0:
                action = rng.choice([-scale, scale], size=7)  # bang-bang
            else:
                action = rng.uniform(-scale, scale, size=7)
            _, _, terminated, truncated, _ = env.step(action.astype(np.float32))
            if terminated or truncated:
                episodes += 1
                env.reset()
        assert episodes >= 5 and len(records) >= 1500
        check_targets(records)
        # the largest increment is the configured max step (clipping at +-1, then scaling)
        steps = np.array([np.abs(t - m).max() for t, m in records])
        assert steps.max() <= env.cfg.action.max_joint_step + 1e-9
    finally:
        env.close()


@pytest.mark.parametrize("scale", [1.0, 10.0, -1.0, -10.0])
def test_joint_targets_clamped_at_limit(scale):
    """j6 turns the gripper about its own axis, so it can be driven to its limit without a
    collision: the targets stop exactly at the limit and the joint stays inside it."""
    env = make("reach")
    try:
        records = record_commands(env)
        env.reset(seed=0, options={"object_xy": FAR_CORNER})
        action = np.zeros(7, dtype=np.float32)
        action[5], action[6] = scale, 1.0
        for _ in range(140):
            obs, _, terminated, truncated, info = env.step(action)
            assert not terminated, info
        check_targets(records)
        limit = FR5_UPPER[5] if scale > 0 else FR5_LOWER[5]
        assert records[-1][0][5] == pytest.approx(limit, abs=1e-12)
        assert abs(measured_arm_positions(env)[5] - limit) < 0.01
        assert obs[5] == pytest.approx(math.copysign(1.0, scale), abs=0.01)
    finally:
        env.close()


# ----------------------------------------------------------------------------- observations
@pytest.mark.parametrize("task", TASKS)
def test_observations_bounded_and_finite(task):
    env = make(task)
    try:
        rng = np.random.default_rng(11)
        obs, _ = env.reset(seed=5)
        observations = [obs]
        for _ in range(2000):
            obs, reward, terminated, truncated, info = env.step(rng.uniform(-1, 1, 7).astype(np.float32))
            observations.append(obs)
            assert np.isfinite(reward)
            if terminated or truncated:
                obs, _ = env.reset()
                observations.append(obs)
        observations = np.array(observations)
        assert observations.dtype == np.float32
        assert np.all(np.isfinite(observations))
        assert observations.min() >= -1.0 and observations.max() <= 1.0
        assert all(env.observation_space.contains(o) for o in observations[::50])
        # The observation carries information: every component varies over the run
        # (the lift of an untouched object aside).
        varying = observations.std(axis=0) > 1e-4
        assert varying[:23].sum() >= 21, observations.std(axis=0)
    finally:
        env.close()


def test_observation_matches_simulator_state():
    """The env's observation is the builder applied to PyBullet's own state."""
    env = make("reach")
    try:
        obs, _ = env.reset(seed=2)
        for _ in range(5):
            obs, *_ = env.step(np.array([0.3, -0.2, 0.1, 0.0, 0.2, -0.1, 1.0], dtype=np.float32))
        spec = env.robot_spec
        q = measured_arm_positions(env)
        np.testing.assert_allclose(obs[:6], (q - (spec.lower_limits + spec.upper_limits) / 2)
                                   / ((spec.upper_limits - spec.lower_limits) / 2), atol=1e-6)
        tcp, rotation = tcp_pose_pybullet(env)
        np.testing.assert_allclose(obs[17:20], rotation[:, 2], atol=1e-6)
        np.testing.assert_allclose(obs[20:23], (env.object_position() - tcp) / 0.8, atol=1e-6)
    finally:
        env.close()


# ----------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("bad", [
    [np.nan, 0, 0, 0, 0, 0, 0], [0, 0, 0, np.inf, 0, 0, 0], [0, 0, 0, 0, 0, 0, -np.inf],
    [0.0] * 6, [0.0] * 8, [], [[0.0] * 7, [0.0] * 7], np.array(["a"] * 7), np.array([None] * 7, dtype=object),
    np.zeros((7, 1), dtype=np.float32), "abcdefg"],
    ids=["nan", "inf", "-inf", "6", "8", "empty", "2x7", "str array", "object array", "7x1", "string"])
def test_bad_actions_raise(bad):
    env = make("reach")
    try:
        env.reset(seed=0)
        with pytest.raises(ValueError):
            env.step(np.array(bad, dtype=np.float64))
        # the environment still works afterwards
        env.step(np.zeros(7, dtype=np.float32))
    finally:
        env.close()


@pytest.mark.parametrize("config", [
    {"no_such_section": 1},
    {"action": {"max_joint_stepp": 0.01}},
    {"reward": {"weights": {"aproach": 1.0}}},
    {"reward": {"mode": "dens"}},
    {"simulation": {"physics_dt": 0.003}},
    {"action": {"smoothing_alpha": 0.0}},
    {"object": {"region_low": [-0.3, -0.3], "region_high": [-0.35, 0.3]}},
    {"randomisation": {"placement_focus_share": 1.5}},
    {"randomisation": {"placement_focus_low": [-0.6, -0.3], "placement_focus_high": [-0.7, 0.3]}},
    {"randomisation": {"placement_focus_low": [-0.7], "placement_focus_high": [-0.6]}},
])
def test_bad_config_raises_config_error(config):
    with pytest.raises(ConfigError):
        FR5Env(task="reach", config=config)


def test_placement_focus_places_its_share_in_the_focus_region_and_nothing_else_when_off():
    """randomisation.placement_focus_share: with share 1 every object lands in the focus strip
    (placed in PyBullet, read back from it); at 0 each seed places its object exactly as with
    the focus fields absent, so that evaluation seeds keep their placements."""
    focus = {"placement_focus_low": [-0.7, -0.3], "placement_focus_high": [-0.6, 0.3]}
    seeds = range(40, 70)

    def placements(randomisation):
        env = FR5Env(task="grasp", config={"randomisation": {"enabled": True, **randomisation}})
        try:
            out = []
            for seed in seeds:
                env.reset(seed=seed)
                position, _ = p.getBasePositionAndOrientation(env.plant.world.object_id, physicsClientId=env.plant.world.client)
                out.append(position[:2])
            return np.array(out)
        finally:
            env.close()

    focused = placements({**focus, "placement_focus_share": 1.0})
    assert np.all((focused[:, 0] >= -0.7) & (focused[:, 0] <= -0.6)), focused[:, 0]
    assert np.ptp(focused[:, 1]) > 0.3  # the strip's whole width, not one point
    uniform = placements({})
    assert np.mean(uniform[:, 0] > -0.6) > 0.5  # most of the region is nearer than the strip
    np.testing.assert_array_equal(placements({**focus, "placement_focus_share": 0.0}), uniform)


def test_an_arm_left_in_place_never_gets_the_object_set_down_inside_its_hand():
    """reset(options={"arm_positions": ...}) (a real arm between episodes) with the gripper down
    at the spot the seed draws: the object is drawn again, clear of the arm (checked with
    PyBullet's own distance query), and stays on the table through the next steps; a seed whose
    draw lies clear is placed exactly as a plain reset places it."""
    env = FR5Env(task="grasp")
    try:
        expert = ScriptedExpert(env)
        moved = 0
        for seed in range(3):
            observation, info = env.reset(seed=seed)
            drawn = info["object_start"].copy()
            while env.tcp_position()[2] > 0.05:  # down around the object, fingers open
                observation, *_ = env.step(expert.act(observation))
            arm = env.joint_positions().tolist()
            _, info = env.reset(seed=seed, options={"arm_positions": arm})
            moved += not np.allclose(info["object_start"], drawn)
            assert not p.getClosestPoints(env.plant.robot.body, env.plant.world.object_id, 0.02,
                                          physicsClientId=env.plant.world.client)
            for _ in range(10):
                env.step(np.zeros(7))
            position, _ = p.getBasePositionAndOrientation(env.plant.world.object_id, physicsClientId=env.plant.world.client)
            np.testing.assert_allclose(position, info["object_start"], atol=2e-3)
        assert moved == 3
        _, info = env.reset(seed=5)
        plain = info["object_start"]
        _, info = env.reset(seed=5, options={"arm_positions": env.robot_spec.home_joint_positions.tolist()})
        np.testing.assert_array_equal(info["object_start"], plain)
    finally:
        env.close()


def test_bad_config_through_gym_make():
    with pytest.raises(ConfigError):
        gym.make("FR5Grasp-v0", config={"grasp": {"lift_heigth": 0.1}})


def test_max_joint_step_over_velocity_limit_refused():
    allowed = float(FR5_VELOCITY.min()) * CONTROL_DT  # 0.063 rad per step
    with pytest.raises(ConfigError, match="slowest rated joint speed"):
        FR5Env(task="reach", config={"action": {"max_joint_step": allowed * 1.05}})
    with pytest.raises(ConfigError):
        FR5Env(task="reach", config={"action": {"max_joint_step": -0.01}})
    env = FR5Env(task="reach", config={"action": {"max_joint_step": allowed}})  # the limit itself is fine
    env.close()


# ----------------------------------------------------------------------------- kinematics
def test_quaternion_z_axis_matches_pybullet():
    """The env reads orientations from PyBullet's quaternions, which are unit length only to
    ~1e-7; the axis must equal PyBullet's own (normalising) matrix column regardless."""
    from fr5_rl.transforms import quaternion_z_axis

    rng = np.random.default_rng(3)
    for _ in range(500):
        quaternion = rng.normal(size=4)
        quaternion *= rng.uniform(0.999, 1.001) / np.linalg.norm(quaternion)
        expected = np.array(p.getMatrixFromQuaternion(quaternion.tolist())).reshape(3, 3)[:, 2]
        np.testing.assert_allclose(quaternion_z_axis(quaternion.tolist()), expected, atol=1e-12)


def test_forward_kinematics_matches_pybullet():
    """fr5_rl.kinematics (what the ROS node uses) equals PyBullet's tcp link pose."""
    env = make("reach")
    try:
        fk = ForwardKinematics(env.robot_spec)
        robot, client = env.plant.robot.body, env.plant.world.client
        arm = joint_indices(env, [f"j{i}" for i in range(1, 7)])
        rng = np.random.default_rng(2024)
        configs = [np.zeros(6), FR5_LOWER.copy(), FR5_UPPER.copy()]
        configs += [rng.uniform(FR5_LOWER, FR5_UPPER) for _ in range(200)]
        worst_position = worst_rotation = 0.0
        for q in configs:
            for index, angle in zip(arm, q):
                p.resetJointState(robot, index, float(angle), 0.0, physicsClientId=client)
            position, rotation = tcp_pose_pybullet(env)
            fk_position, fk_rotation = fk.tcp_pose(q)
            worst_position = max(worst_position, float(np.linalg.norm(fk_position - position)))
            worst_rotation = max(worst_rotation, float(np.abs(fk_rotation - rotation).max()))
        assert worst_position < 1e-6, worst_position
        assert worst_rotation < 1e-6, worst_rotation
        # and the tcp is where the flange is, 0.17 m further along the flange z axis
        flange_position, flange_rotation = fk.flange_pose(configs[5])
        tcp_position, _ = fk.tcp_pose(configs[5])
        np.testing.assert_allclose(tcp_position - flange_position, 0.17 * flange_rotation[:, 2], atol=1e-12)
    finally:
        env.close()
