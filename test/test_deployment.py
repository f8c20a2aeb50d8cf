"""The 50 Hz deployment step without ROS: each hold reason, the safety gate, and commands that
respect the FR5's joint and velocity limits."""
import math

import numpy as np
import pytest

from fr5_rl.config import load_robot_spec
from fr5_rl.env_config import load_env_config
from fr5_rl.deploy.bundle import ModelFilesError
from fr5_rl.deploy.deployment import Command, DeploymentStep, Hold, HoldReason, SafetyGate, StepInputs
from fr5_rl.deploy.joint_state import (ArmJointState, FreshStateWait, JointStateReader, Reading,
                                        velocities_from_positions)
from fr5_rl.deploy.policy import Policy

ROBOT = load_robot_spec()
ENV_CFG = load_env_config()
DT = ENV_CFG.simulation.control_dt
NOW = 100.0
TARGET = (-0.5, 0.1, 0.03)  # m, base_link: on the table in front of the arm


class FixedPolicy(Policy):
    """A policy that always returns the same action (the step's logic is what is under test)."""

    backend = "fixed"

    def __init__(self, action, task="reach"):
        super().__init__({"task": task, "algo": "ppo", "observation_size": 23 if task == "reach" else 24,
                          "action_size": 7})
        self.action = np.asarray(action, dtype=np.float64)
        self.seen = []

    def _act(self, observation):
        self.seen.append(observation)
        return self.action


def make_step(action=(1, -1, 0.5, 0, 0, 0, 1), **kwargs) -> DeploymentStep:
    return DeploymentStep(FixedPolicy(action), ROBOT, ENV_CFG, joint_state_timeout=0.1, target_timeout=0.5, **kwargs)


def joint_reading(positions=None, received=NOW, velocities=None, width=0.08) -> Reading:
    positions = ROBOT.home_joint_positions if positions is None else np.asarray(positions, dtype=float)
    velocities = np.zeros(6) if velocities is None else np.asarray(velocities, dtype=float)
    return Reading(ArmJointState(positions, velocities, width), received)


def partial_reading() -> Reading:
    reader = JointStateReader(ROBOT.joint_names, ())
    reader.update(["j1", "j2"], [0.0, 0.0], [], 0.0, NOW)
    return reader.reading()


def inputs(joints="good", target="good", now=NOW) -> StepInputs:
    joints = joint_reading() if joints == "good" else joints
    target = Reading(TARGET, NOW) if target == "good" else target
    return StepInputs(now, joints, target)


def test_good_inputs_give_a_command_within_limits():
    step = make_step()
    result = step(inputs())
    assert isinstance(result, Command), result
    targets = np.array(result.arm_positions)
    assert targets.shape == (6,) and np.isfinite(targets).all()
    assert np.all(np.abs(targets - ROBOT.home_joint_positions) <= ROBOT.velocity_limits * DT + 1e-12)
    assert result.gripper_width == pytest.approx(ROBOT.max_opening_width)  # action +1 = open
    assert result.target_in_base == TARGET and step.last_hold is None


@pytest.mark.parametrize("case, expected", [
    (lambda s: setattr(s, "enabled", False) or inputs(), HoldReason.DISABLED),
    (lambda s: inputs(joints=None), HoldReason.NO_JOINT_STATE),
    (lambda s: inputs(joints=partial_reading()), HoldReason.JOINT_STATE_INVALID),
    (lambda s: inputs(joints=joint_reading(received=NOW - 0.15)), HoldReason.JOINT_STATE_STALE),
    (lambda s: inputs(target=None), HoldReason.NO_TARGET),
    (lambda s: inputs(target=Reading(None, NOW, "no transform camera_link -> base_link")), HoldReason.TARGET_UNAVAILABLE),
    (lambda s: inputs(target=Reading(TARGET, NOW - 0.6)), HoldReason.TARGET_STALE),
    (lambda s: inputs(target=Reading((math.nan, 0.0, 0.0), NOW)), HoldReason.TARGET_INVALID),
    (lambda s: inputs(target=Reading((0.0, 0.0), NOW)), HoldReason.TARGET_INVALID),
    (lambda s: inputs(joints=joint_reading(velocities=[0, 0, math.inf, 0, 0, 0])), HoldReason.OBSERVATION_INVALID),
    # Measured beyond j1's upper limit (3.0543 rad): the clamped target is a jump back.
    (lambda s: inputs(joints=joint_reading(positions=[3.2, -1.57, 1.57, -1.57, -1.57, 0.0])), HoldReason.UNSAFE_COMMAND),
], ids=lambda v: v.name if isinstance(v, HoldReason) else "")
def test_each_hold_reason(case, expected):
    step = make_step()
    result = step(case(step))
    assert isinstance(result, Hold) and result.reason is expected, result
    assert result.detail and step.last_hold == result
    assert not step.policy.seen or expected is HoldReason.UNSAFE_COMMAND  # no inference on bad inputs


def test_a_hold_sends_no_stale_gripper_width():
    """The width a held period computed never becomes the next observation's commanded width."""
    step = make_step(action=(0, 0, 0, 0, 0, 0, -1))
    step(inputs(joints=joint_reading(positions=[3.2, -1.57, 1.57, -1.57, -1.57, 0.0])))
    assert step.gripper_command_width == pytest.approx(ROBOT.max_opening_width)


def test_resuming_after_a_hold_restarts_the_action_filter():
    fresh = make_step()(inputs())
    step = make_step()
    step(inputs())
    second = step(inputs())  # the filter carries momentum: a bigger step than the first
    assert not np.allclose(second.arm_positions, fresh.arm_positions)
    assert isinstance(step(inputs(target=None)), Hold)
    resumed = step(inputs())
    assert np.allclose(resumed.arm_positions, fresh.arm_positions)


def hand_over_target(height: float = 0.04) -> np.ndarray:
    """Joint positions (rad) with the tcp ``height`` (m) above TARGET, pointing down."""
    from fr5_rl.kinematics import ForwardKinematics, InverseKinematics

    kinematics = ForwardKinematics(ROBOT)
    _, down = kinematics.tcp_pose(ROBOT.home_joint_positions)
    joints, converged = InverseKinematics(kinematics).solve(
        ROBOT.home_joint_positions, (TARGET[0], TARGET[1], TARGET[2] + height), np.asarray(down).ravel().tolist(),
        max_iterations=50)
    assert converged
    return np.array(joints)


def rise_on_a_stale_target(target, periods=300):
    """Run a closing policy over ``target`` (m, base_link) once, then the target stale with an arm
    that follows its commands: (the step, every command or hold, the tcp heights, the tcp pose
    at the start)."""
    from fr5_rl.kinematics import ForwardKinematics

    kinematics = ForwardKinematics(ROBOT)
    step = make_step(action=(0, 0, 0, 0, 0, 0, -1), stale_target_rise=0.2, stale_target_rise_speed=0.25)
    positions = hand_over_target()
    first = step(inputs(joints=joint_reading(positions), target=Reading(target, NOW)))
    assert isinstance(first, Command) and first.gripper_width == pytest.approx(0.0)  # the policy closed it
    start = kinematics.tcp_pose(positions)
    results, heights = [], []
    for _ in range(periods):
        result = step(inputs(joints=joint_reading(positions), target=Reading(target, NOW - 0.6)))
        results.append(result)
        if isinstance(result, Hold):
            break
        assert result.target_in_base is None and "stale" in step.rising
        targets = np.array(result.arm_positions)
        assert np.all(np.abs(targets - positions) <= ROBOT.velocity_limits * DT + 1e-12)
        positions = targets  # an arm that follows its command
        position, rotation = kinematics.tcp_pose(positions)
        heights.append(position[2])
        assert np.allclose(position[:2], start[0][:2], atol=1e-4)  # straight up
        assert np.allclose(rotation, start[1], atol=1e-4)
    return step, results, np.array(heights), positions


def test_a_stale_target_lets_go_of_a_standing_object_rises_clear_holds_then_the_policy_resumes():
    """With ``stale_target_rise``, over an object last seen standing: the fingers open with the
    arm still for stale_target_let_go, then the tcp rises straight up (its rotation kept) until
    it is that far above the last target, holds there, and hands back to the policy once a fresh
    target comes."""
    step, results, heights, positions = rise_on_a_stale_target(TARGET)
    opening = step.let_go_periods
    assert opening == int(round(0.4 / DT))  # stale_target_let_go's default
    assert all(r.gripper_width == pytest.approx(ROBOT.max_opening_width) for r in results[:-1])
    assert np.ptp(heights[:opening]) < 1e-9 and np.all(np.diff(heights[opening:]) > 0)
    assert np.max(np.diff(heights)) <= 0.25 * DT + 1e-6
    last = results[-1]
    assert isinstance(last, Hold) and last.reason is HoldReason.TARGET_STALE and "risen" in last.detail
    assert step.rising is None
    assert heights[-1] == pytest.approx(TARGET[2] + 0.2, abs=1e-3)
    assert isinstance(step(inputs(joints=joint_reading(positions), target=Reading(TARGET, NOW - 0.6))), Hold)
    resumed = step(inputs(joints=joint_reading(positions)))
    assert isinstance(resumed, Command) and resumed.target_in_base == TARGET


def test_a_stale_target_last_seen_in_the_air_keeps_the_grip_as_it_rises():
    """Last seen in the air, the object is carried: the fingers stay as commanded, and the rise
    begins at once."""
    carried = (TARGET[0], TARGET[1], ENV_CFG.object_rest_z() + 0.05)
    _, results, heights, _ = rise_on_a_stale_target(carried)
    assert all(r.gripper_width == pytest.approx(0.0) for r in results[:-1])
    assert np.all(np.diff(heights) > 0) and heights[-1] == pytest.approx(carried[2] + 0.2, abs=1e-3)


def test_without_a_rise_or_a_target_acted_on_a_stale_target_holds_at_once():
    stale = Reading(TARGET, NOW - 0.6)
    assert make_step(stale_target_rise=0.2)(inputs(target=stale)).reason is HoldReason.TARGET_STALE
    step = make_step()  # stale_target_rise 0: the default
    step(inputs())
    assert step(inputs(target=stale)).reason is HoldReason.TARGET_STALE and step.rising is None


def test_the_policy_after_a_rise_starts_without_the_rises_momentum():
    low = joint_reading(hand_over_target())
    fresh = make_step()(inputs(joints=low))
    step = make_step(stale_target_rise=0.2)
    step(inputs(joints=low))
    assert isinstance(step(inputs(joints=low, target=Reading(TARGET, NOW - 0.6))), Command) and step.rising
    resumed = step(inputs(joints=low))
    assert np.allclose(resumed.arm_positions, fresh.arm_positions)


def test_a_new_object_restarts_the_action_filter():
    fresh = make_step()(inputs(target=Reading((-0.4, -0.2, 0.03), NOW)))
    step = make_step()
    step(inputs())
    moved = step(inputs(target=Reading((-0.4, -0.2, 0.03), NOW)))  # 0.32 m away: a new object
    assert np.allclose(moved.arm_positions, fresh.arm_positions)


def test_observation_matches_the_environment_builder():
    """The step feeds the policy the observation the environments build from the same state."""
    from fr5_rl.kinematics import ForwardKinematics
    from fr5_rl.observation import ObservationBuilder

    step = make_step()
    step(inputs())
    position, rotation = ForwardKinematics(ROBOT).tcp_pose(ROBOT.home_joint_positions)
    expected = ObservationBuilder(ROBOT, ENV_CFG.observation, False).build_from(
        ROBOT.home_joint_positions, np.zeros(6), 0.08, ROBOT.max_opening_width, position, rotation[:, 2], TARGET)
    np.testing.assert_allclose(step.policy.seen[0], expected, atol=1e-7)


def test_wrong_policy_size_is_refused():
    assert DeploymentStep(FixedPolicy([0] * 7, task="grasp"), ROBOT, ENV_CFG, 0.1, 0.5).builder.size == 24
    policy = FixedPolicy([0] * 7)
    policy.observation_size = 24
    with pytest.raises(ModelFilesError, match="observation values"):
        DeploymentStep(policy, ROBOT, ENV_CFG, 0.1, 0.5)


# ----------------------------------------------------------------------------- the safety gate
GATE = SafetyGate(ROBOT, DT)
HOME = ROBOT.home_joint_positions


@pytest.mark.parametrize("targets, words", [
    (HOME[:5], "5 joint targets"),
    (np.r_[HOME[:5], math.nan], "NaN"),
    (np.r_[ROBOT.upper_limits[0] + 0.01, HOME[1:]], "j1 target"),
    (HOME + np.r_[0, 0, 0.07, 0, 0, 0], "j3 would move 0.070 rad"),
], ids=["length", "nan", "limit", "velocity"])
def test_gate_refuses(targets, words):
    problem = GATE.check(targets, HOME)
    assert problem is not None and words in problem, problem


def test_gate_passes_a_step_at_the_velocity_limit():
    assert GATE.check(HOME + ROBOT.velocity_limits * DT * 0.999, HOME) is None
    assert GATE.check(HOME + ROBOT.velocity_limits * DT * 1.01, HOME) is not None


# ----------------------------------------------------------------------------- adversarial inputs
@pytest.mark.parametrize("target, expected", [
    (Reading((50.0, 0.0, 0.03), NOW), HoldReason.TARGET_OUT_OF_WORKSPACE),
    (Reading((-0.5, 0.1, -0.5), NOW), HoldReason.TARGET_OUT_OF_WORKSPACE),  # under the table
    (Reading(TARGET, NOW, stamp=5000.0 - 3600.0), HoldReason.TARGET_STALE),  # an hour-old detection
    (Reading(TARGET, NOW, stamp=5000.0 + 3600.0), HoldReason.TARGET_FROM_FUTURE),
    (Reading(TARGET, NOW, stamp=5000.0 - 0.6), HoldReason.TARGET_STALE),  # arrived now, captured 0.6 s ago
], ids=["50 m away", "below the table", "stamp an hour old", "stamp an hour ahead", "captured 0.6 s ago"])
def test_targets_that_must_not_drive_the_arm(target, expected):
    result = make_step()(StepInputs(NOW, joint_reading(), target, stamp_now=5000.0))
    assert isinstance(result, Hold) and result.reason is expected, result


def test_fresh_stamp_and_edge_of_workspace_are_accepted():
    edge = (ENV_CFG.workspace.low[0] - 0.04, 0.0, 0.03)  # within the 5 cm margin
    for target in (Reading(TARGET, NOW, stamp=4999.99), Reading(edge, NOW, stamp=5000.0)):
        assert isinstance(make_step()(StepInputs(NOW, joint_reading(), target, stamp_now=5000.0)), Command)


ARM = list(ROBOT.joint_names)
FINGERS = list(ROBOT.finger_joint_names)


def reader() -> JointStateReader:
    return JointStateReader(ROBOT.joint_names, ROBOT.finger_joint_names)


def test_a_joint_named_twice_is_refused_until_a_good_message():
    joints = reader()
    home = list(ROBOT.home_joint_positions)
    problem = joints.update(ARM + ["j3"], home + [home[2] + 0.47], [0.0] * 7, 1.0, NOW)
    assert problem and "j3 twice" in problem
    reading = joints.reading()
    assert reading.value is None and "twice" in reading.problem
    assert isinstance(make_step()(inputs(joints=reading)), Hold)
    joints.update(ARM, home, [0.0] * 6, 1.01, NOW + 0.01)
    assert joints.reading().problem is None


def test_arm_and_fingers_in_separate_messages_merge():
    joints = reader()
    home = list(ROBOT.home_joint_positions)
    for k in range(20):  # alternating publishers, as an arm driver and a gripper driver do
        if k % 2:
            joints.update(FINGERS, [0.02, 0.02], [0.0, 0.0], 1.0 + k * 0.01, NOW + k * 0.01)
        else:
            joints.update(list(reversed(ARM)), list(reversed(home)), [0.0] * 6, 1.0 + k * 0.01, NOW + k * 0.01)
        reading = joints.reading()
        assert reading.problem is None, reading.problem
        np.testing.assert_allclose(reading.value.positions, home)
    assert reading.value.gripper_width == pytest.approx(0.04)
    assert isinstance(make_step()(inputs(joints=reading, now=NOW + 0.2)), Command)


def test_one_silent_joint_makes_the_state_stale():
    joints = reader()
    home = list(ROBOT.home_joint_positions)
    joints.update(ARM, home, [0.0] * 6, 1.0, NOW - 1.0)
    joints.update(ARM[:5], home[:5], [0.0] * 5, 2.0, NOW)  # j6 not heard from for a second
    reading = joints.reading()
    assert reading.received == pytest.approx(NOW - 1.0)
    result = make_step()(inputs(joints=reading))
    assert isinstance(result, Hold) and result.reason is HoldReason.JOINT_STATE_STALE


@pytest.mark.parametrize("names, positions, velocities, words", [
    (ARM, [0.0] * 5, [], "names but 5 positions"),
    (ARM, [0.0] * 6, [0.0] * 3, "3 velocities"),
    (ARM, [0.0, math.nan, 0, 0, 0, 0], [], "NaN"),
    (ARM, [0.0] * 6, [0, 0, 0, 0, 0, math.inf], "NaN or inf"),
    (ARM, ["a"] * 6, [], "not a number"),
])
def test_malformed_messages_are_refused(names, positions, velocities, words):
    problem = reader().update(names, positions, velocities, 1.0, NOW)
    assert problem and words in problem, problem


def test_unknown_joints_are_ignored_and_missing_ones_named():
    joints = reader()
    joints.update(["joint1", "j1", "j2"], [9.0, 0.1, 0.2], [], 1.0, NOW)
    reading = joints.reading()
    assert reading.value is None and "j3" in reading.problem


def test_velocities_are_estimated_per_joint_when_left_out():
    joints = reader()
    home = np.array(ROBOT.home_joint_positions)
    joints.update(ARM, list(home), [], 1.0, NOW)
    joints.update(ARM, list(home + 0.01), [], 1.02, NOW + 0.02)
    np.testing.assert_allclose(joints.reading().value.velocities, 0.5, atol=1e-9)


# ----------------------------------------------------------------------------- the safety zone
from fr5_rl.deploy.deployment import SafetyZone, segment_distance  # noqa: E402

ZONE = SafetyZone(ROBOT, ENV_CFG)
# Configurations where the gripper is inside the forearm (found by sampling the joint limits).
SELF_CONTACTS = [[-1.74, -0.72, 1.73, 1.26, -2.13, -0.11], [2.84, -2.17, -1.16, 0.55, -2.29, 1.43],
                 [1.52, -1.92, -1.64, 0.9, -2.95, -1.2]]


def test_segment_distance():
    o, x = np.zeros(3), np.array([1.0, 0, 0])
    assert segment_distance(o, x, np.array([0.5, 1, 0]), np.array([0.5, 2, 0])) == pytest.approx(1.0)
    assert segment_distance(o, x, np.array([0.5, -1, 0]), np.array([0.5, 1, 0])) == pytest.approx(0.0)  # crossing
    assert segment_distance(o, x, np.array([2.0, 0, 0]), np.array([3.0, 0, 0])) == pytest.approx(1.0)  # collinear
    assert segment_distance(o, o, np.array([0, 3.0, 4]), np.array([0, 3.0, 4])) == pytest.approx(5.0)  # points


def test_zone_refuses_the_table_and_self_contact():
    assert ZONE.check(ROBOT.home_joint_positions) is None
    down = ROBOT.home_joint_positions + np.array([0, 1.2, 0, 0, 0, 0])  # shoulder swung into the table
    assert "table" in ZONE.check(down)
    for q in SELF_CONTACTS:
        assert "forearm and gripper" in (ZONE.check(q) or ""), q


def test_zone_agrees_with_the_simulator_geometry():
    """The capsules are not invented: PyBullet's collision shapes of the same URDF interpenetrate
    in the self-contact configurations, and are apart at home."""
    import pybullet as p

    from fr5_rl.envs import FR5Env

    env = FR5Env(task="reach")
    env.reset(seed=0)
    body, client = env.plant.robot.body, env.plant.world.client
    links = {p.getJointInfo(body, j, physicsClientId=client)[12].decode(): j
             for j in range(p.getNumJoints(body, physicsClientId=client))}
    gripper = [links[name] for name in ("gripper_base_link", "finger_left_link", "finger_right_link")]

    def forearm_gripper_distance(q):
        env.plant.robot.reset(np.asarray(q, dtype=float), ROBOT.max_opening_width)
        return min(c[8] for g in gripper
                   for c in p.getClosestPoints(body, body, 1.0, links["forearm_Link"], g, physicsClientId=client))

    for q in SELF_CONTACTS:
        assert forearm_gripper_distance(q) < 0.0, q
    assert forearm_gripper_distance(ROBOT.home_joint_positions) > 0.05
    env.close()


@pytest.mark.parametrize("task", ["reach", "grasp"])
def test_zone_never_stops_the_expert(task):
    """No false alarm: along successful expert episodes every configuration is inside the zone
    (the shipped policies were checked the same way over 40 episodes each, docs/benchmarks.md)."""
    from fr5_rl.envs import FR5Env
    from fr5_rl.expert import ScriptedExpert

    env = FR5Env(task=task)
    expert = ScriptedExpert(env)
    checked = 0
    for seed in range(8):
        obs, _ = env.reset(seed=3_000_000 + seed)
        expert.reset()
        done, problems = False, []
        while not done:
            obs, _, terminated, truncated, info = env.step(expert.act(obs))
            done = terminated or truncated
            problems.append(ZONE.check(env.joint_positions()))
            checked += 1
        if info["is_success"]:
            assert not any(problems), (seed, [x for x in problems if x][:1])
    env.close()
    assert checked > 100


def test_the_step_holds_a_command_into_the_table():
    down = ROBOT.home_joint_positions + np.array([0, 1.2, 0, 0, 0, 0])
    result = make_step(action=(0, 0, 0, 0, 0, 0, 1))(inputs(joints=joint_reading(positions=down)))
    assert isinstance(result, Hold) and result.reason is HoldReason.UNSAFE_COMMAND and "table" in result.detail


def test_start_episode_forgets_the_filter_and_opens_the_gripper():
    """After ``start_episode`` the step acts as a fresh one: the first period of a new episode
    (the lockstep simulator's reset, an operator's new object) matches training's first step."""
    fresh = make_step(action=(1, -1, 0.5, 0, 0, 0, -1))(inputs())
    step = make_step(action=(1, -1, 0.5, 0, 0, 0, -1))
    step(inputs())
    step(inputs())
    assert step.gripper_command_width < ROBOT.max_opening_width  # action -1: closing
    step.start_episode()
    assert step.gripper_command_width == pytest.approx(ROBOT.max_opening_width)
    again = step(inputs())
    assert np.allclose(again.arm_positions, fresh.arm_positions)
    assert np.allclose(step.policy.seen[-1], step.policy.seen[0])  # the same first observation


def test_reading_carries_the_oldest_arm_stamp():
    reader = JointStateReader(ROBOT.joint_names, ROBOT.finger_joint_names)
    reader.update(list(ROBOT.joint_names[:3]), [0.0] * 3, [], 5.0, NOW)
    reader.update(list(ROBOT.joint_names[3:]), [0.0] * 3, [], 5.02, NOW)
    assert reader.reading().stamp == pytest.approx(5.0)
    reader.update(list(ROBOT.joint_names[:3]), [0.0] * 3, [], 5.04, NOW)
    assert reader.reading().stamp == pytest.approx(5.02)
    reader.update(list(ROBOT.joint_names), [0.0] * 6, [], 0.0, NOW)  # a driver without stamps
    assert reader.reading().stamp == 0.0


# ----------------------------------------------------------------------------- previous actions
class ScriptedPolicy(Policy):
    """Returns the given actions one after the other and records what it was shown."""

    backend = "scripted"

    def __init__(self, actions, task, observation_size):
        super().__init__({"task": task, "algo": "ppo", "observation_size": observation_size, "action_size": 7})
        self.actions = list(actions)
        self.seen = []

    def _act(self, observation):
        self.seen.append(observation)
        return np.asarray(self.actions[len(self.seen) - 1], dtype=np.float64)


def run_beside_the_environment(task: str, overrides, actions, size: int, seed: int) -> list:
    """Feed a DeploymentStep the environment's state period by period while the environment
    steps ``actions``; assert that the node's observation is the environment's every period.
    Returns the environment's observations (the first from the reset, then after each action)."""
    from fr5_rl.envs import FR5Env
    from fr5_rl.objects import yaw_of

    env = FR5Env(task, config=overrides)
    policy = ScriptedPolicy(actions, task, size)
    step = DeploymentStep(policy, ROBOT, load_env_config(overrides), joint_state_timeout=0.1, target_timeout=0.5)
    observations = [env.reset(seed=seed)[0]]
    for period, action in enumerate(actions):
        state = env.task_state()
        joints = Reading(ArmJointState(np.asarray(state.joint_positions), np.asarray(state.joint_velocities),
                                       state.gripper_width), NOW)
        # What the node takes from tf: the object's position and yaw, its shape, the goal.
        target = Reading((*state.object_position, yaw_of(state.object_quaternion)), NOW)
        shape = Reading(env.episode.plant.object_shape, NOW)
        goal = Reading(env.episode.draws.goal, NOW) if env.episode.draws.goal is not None else None
        command = step(StepInputs(NOW, joints, target, object_shape=shape, goal=goal))
        assert isinstance(command, Command), command
        np.testing.assert_allclose(policy.seen[period], observations[-1], atol=1e-6, err_msg=f"period {period}")
        observations.append(env.step(action)[0])
    env.close()
    return observations


@pytest.mark.parametrize("latency", [0, 2])
def test_the_step_observes_the_actions_it_sent_as_the_environment_does(latency):
    """With ``observation.previous_actions``, the node's observation is the environment's, period
    by period, fed the same states and actions; with latency too (the block holds what was
    sent, not what the arm is doing yet)."""
    overrides = {"observation": {"previous_actions": 3}, "randomisation": {
        "enabled": True, "action_latency_steps": [latency, latency], "object_size_scale": [1, 1],
        "object_mass_scale": [1, 1], "friction_scale": [1, 1], "joint_damping": [0, 0]}}
    actions = np.random.default_rng(7).uniform(-1.2, 1.2, (8, 7))  # some beyond +-1: clipped by both
    observations = run_beside_the_environment("grasp", overrides, actions, 24 + 18, seed=3)
    sent = np.clip(actions[-3:, :6], -1, 1)[::-1].reshape(-1)
    np.testing.assert_allclose(observations[-1][24:], sent, atol=1e-7)


def test_the_step_builds_the_joint_step_hint_as_the_environment_does():
    """With ``observation.joint_step_hint`` (config/ppo_reach.yaml), the node's observation is the
    environment's, hint included, period by period, fed the same states."""
    from fr5_rl.training.algorithms import load_hyperparameters

    overrides = {"observation": load_hyperparameters("ppo", "reach").env["observation"]}
    assert overrides["observation"]["joint_step_hint"], "config/ppo_reach.yaml should turn the hint on"
    actions = np.random.default_rng(5).uniform(-1.0, 1.0, (8, 7))
    observations = run_beside_the_environment("reach", overrides, actions, 23 + 6, seed=4)
    assert min(np.abs(observation[23:]).max() for observation in observations) > 0.05  # the hint, not zeros


def test_a_hold_clears_the_previous_actions():
    """After a hold the arm stood still: the block reads zeros again, as at an episode start."""
    env_cfg = load_env_config({"observation": {"previous_actions": 2}})
    policy = ScriptedPolicy([[0.5] * 7] * 3, "reach", 23 + 12)
    step = DeploymentStep(policy, ROBOT, env_cfg, joint_state_timeout=0.1, target_timeout=0.5)
    step(inputs())
    step(inputs())
    np.testing.assert_allclose(policy.seen[1][23:], [0.5] * 6 + [0.0] * 6)
    assert isinstance(step(inputs(target=None)), Hold)
    step(inputs())
    np.testing.assert_allclose(policy.seen[2][23:], [0.0] * 12)


def test_an_evaluation_keeps_the_settings_the_policy_depends_on_and_nothing_else():
    """evaluate.py runs the registered task: the training's randomisation and reward go, the
    observation and action settings stay (or the environment would build what the policy cannot take)."""
    meta = {"task": "grasp", "algo": "ppo", "observation_size": 42, "action_size": 7, "env_overrides": {
        "observation": {"previous_actions": 3}, "action": {"smoothing_alpha": 0.6},
        "simulation": {"control_dt": 0.02, "physics_dt": 0.004}, "reward": {"failure_penalty": 10.0},
        "randomisation": {"enabled": True, "action_latency_steps": [0, 2]}}}
    assert Policy(meta).deployment_overrides() == {"observation": {"previous_actions": 3},
                                                   "action": {"smoothing_alpha": 0.6},
                                                   "simulation": {"control_dt": 0.02}}
    assert Policy({**meta, "env_overrides": {}}).deployment_overrides() == {}


@pytest.mark.parametrize("driver, trained, estimated", [
    ("driver", "measured", False),   # true velocities, a policy trained on true ones
    ("positions", "measured", True),  # the FAIRINO driver's 0.0: estimate whatever the policy saw
    ("driver", "positions", True),    # a policy trained on the estimate gets it behind every driver
    ("positions", "positions", True),
])
def test_the_node_estimates_velocities_when_the_driver_or_the_training_says_so(driver, trained, estimated):
    assert velocities_from_positions(driver, trained) is estimated


def test_a_new_episode_restarts_the_velocity_estimate_as_the_environment_does():
    """The environment's first observation of an episode has velocities 0.0; the node's estimate
    from the last episode's final state (the arm teleported, or moved by hand) must not leak in."""
    reader = JointStateReader(ROBOT.joint_names, ROBOT.finger_joint_names, velocities_from_positions=True)
    names = list(ROBOT.joint_names)
    reader.update(names, [0.0] * 6, [], 1.00, 1.00)
    reader.update(names, [0.01] * 6, [], 1.02, 1.02)
    assert reader.reading().value.velocities == pytest.approx([0.5] * 6)
    reader.restart_estimates()
    reader.update(names, [0.3] * 6, [], 1.04, 1.04)
    assert reader.reading().value.velocities == pytest.approx([0.0] * 6)  # not (0.3 - 0.01) / 0.02
    reader.update(names, [0.31] * 6, [], 1.06, 1.06)
    assert reader.reading().value.velocities == pytest.approx([0.5] * 6)  # estimating again from there


def test_estimates_from_a_fast_driver_span_a_control_period():
    """A 200 Hz driver with 1 ms of stamp jitter: from consecutive messages the estimate would
    swing by +-40 %; over the 18 ms the environment's once-a-period samples span, by +-10 %."""
    names = list(ROBOT.joint_names)
    reader = JointStateReader(ROBOT.joint_names, ROBOT.finger_joint_names, velocities_from_positions=True,
                              estimate_interval=0.018)
    true_speed, estimates = 0.5, []
    for k in range(60):
        jitter = 0.001 if k % 2 else -0.001
        stamp = 1.0 + 0.005 * k + jitter
        reader.update(names, [true_speed * (stamp - 1.0)] * 6, [], stamp, stamp)
        if k >= 5:
            estimates.append(reader.reading().value.velocities[0])
    assert max(abs(v - true_speed) for v in estimates) <= 0.1 * true_speed
    # At 50 Hz (messages 20 ms apart) it is the consecutive-message estimate, as before.
    slow = JointStateReader(ROBOT.joint_names, ROBOT.finger_joint_names, velocities_from_positions=True,
                            estimate_interval=0.018)
    slow.update(names, [0.0] * 6, [], 1.00, 1.00)
    slow.update(names, [0.01] * 6, [], 1.02, 1.02)
    slow.update(names, [0.03] * 6, [], 1.04, 1.04)
    assert slow.reading().value.velocities == pytest.approx([1.0] * 6)


def _arm_reading(reader: JointStateReader, positions, stamp: float, received: float):
    reader.update(ARM, positions, [], stamp, received)
    return reader.reading()


def test_a_period_waits_only_for_a_state_no_period_used():
    reader = JointStateReader(ROBOT.joint_names, ROBOT.finger_joint_names)
    fresh = FreshStateWait(0.015)
    assert fresh.is_new(None)  # nothing yet: the step holds at once, there is nothing to wait for
    first = _arm_reading(reader, [0.0] * 6, stamp=1.00, received=10.00)
    assert fresh.is_new(first)
    fresh.used(first)
    assert not fresh.is_new(reader.reading())  # the same message again: wait
    # A finger update does not make the arm's state new.
    reader.update(list(ROBOT.finger_joint_names), [0.02, 0.02], [], 1.01, 10.01)
    assert not fresh.is_new(reader.reading())
    second = _arm_reading(reader, [0.01] * 6, stamp=1.02, received=10.02)
    assert fresh.is_new(second)
    fresh.used(second)
    # An unusable state is never waited on: the period holds on it.
    reader.update(ARM[:1], [float("nan")], [], 1.04, 10.04)
    assert fresh.is_new(reader.reading())
    with pytest.raises(ValueError, match=">= 0"):
        FreshStateWait(-0.001)
    with pytest.raises(ValueError, match=">= 0"):
        FreshStateWait(float("nan"))


def test_a_period_waits_past_a_state_older_than_the_largest_age():
    """fresh_state_max_age: a new state that arrived longer ago than it is waited past too (the
    phase between a 50 Hz driver and the timer left states 12 ms old at every tick, and the place
    model did 0/20 behind the emulated FAIRINO driver); given no clock, age is not asked."""
    reader = JointStateReader(ROBOT.joint_names, ROBOT.finger_joint_names)
    fresh = FreshStateWait(0.015, max_age_s=0.005)
    state = _arm_reading(reader, [0.0] * 6, stamp=1.00, received=10.000)
    assert fresh.is_new(state, now=10.004)
    assert not fresh.is_new(state, now=10.012)  # 12 ms old: wait for the next one
    assert fresh.is_new(state)  # no clock: new is enough
    assert FreshStateWait(0.015).is_new(state, now=10.012)  # no largest age: any will do
    fresh.used(state)
    assert not fresh.is_new(state, now=10.001)  # used: never new, however young
    with pytest.raises(ValueError, match=">= 0"):
        FreshStateWait(0.015, max_age_s=-0.001)


# ----------------------------------------------------------------------------- pick and place
PLACE_CFG = load_env_config({"object": {"variety": {"enabled": True}}, "observation": {"object_features": True}})


def place_step() -> DeploymentStep:
    from fr5_rl.observation import observation_size

    policy = ScriptedPolicy([[0.0] * 7] * 10, "place", observation_size("place", PLACE_CFG.observation))
    return DeploymentStep(policy, ROBOT, PLACE_CFG, joint_state_timeout=0.1, target_timeout=0.5)


def place_inputs(target=(*TARGET, 0.3), shape="box", goal=(-0.6, -0.1, 1.0)) -> StepInputs:
    from fr5_rl.objects import ObjectShape

    shape = Reading(ObjectShape("box", (0.06, 0.04, 0.05)), NOW) if shape == "box" else shape
    goal = Reading(goal, NOW) if isinstance(goal, tuple) else goal
    return StepInputs(NOW, joint_reading(), Reading(target, NOW), object_shape=shape, goal=goal)


@pytest.mark.parametrize("change, reason, words", [
    ({"shape": None}, HoldReason.NO_OBJECT_SHAPE, "shape"),
    ({"shape": Reading(None, NOW, "a SolidPrimitive of type SPHERE")}, HoldReason.OBJECT_SHAPE_INVALID, "SPHERE"),
    ({"goal": None}, HoldReason.NO_GOAL, "goal"),
    ({"goal": Reading(None, NOW, "no transform conveyor -> base_link")}, HoldReason.GOAL_INVALID, "conveyor"),
    ({"goal": (-0.6, math.nan, 0.0)}, HoldReason.GOAL_INVALID, "finite"),
    ({"goal": (-0.6, -0.1)}, HoldReason.GOAL_INVALID, "x, y"),
    ({"goal": (-1.2, 0.0, 0.0)}, HoldReason.GOAL_INVALID, "placement region"),
    ({"target": TARGET}, HoldReason.TARGET_INVALID, "yaw"),
], ids=["no-shape", "bad-shape", "no-goal", "goal-tf", "goal-nan", "goal-short", "goal-outside", "no-yaw"])
def test_a_place_policy_holds_without_a_usable_shape_goal_or_yaw(change, reason, words):
    step = place_step()
    result = step(place_inputs(**change))
    assert isinstance(result, Hold) and result.reason is reason and words in result.detail, result
    assert step.policy.seen == []  # the policy never ran on a partial observation
    assert isinstance(step(place_inputs()), Command)  # and runs once all is there


def test_the_goal_and_yaw_reach_the_policy_by_the_objects_symmetry():
    """A box turned by half a turn, and its goal with it, is the same observation (symmetry 2);
    a quarter turn is not."""
    seen = []
    for turn in (0.0, math.pi, math.pi / 2):
        step = place_step()
        step(place_inputs(target=(*TARGET, 0.3 + turn), goal=(-0.6, -0.1, 1.0 + turn)))
        seen += step.policy.seen
    first, half, quarter = seen
    np.testing.assert_allclose(first, half, atol=1e-9)
    assert not np.allclose(first, quarter, atol=1e-3)
