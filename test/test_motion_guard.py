"""What the real arm adds around the policy (fr5_rl.motion_guard, the joint-state reader):
the slow start move and its refusal, the ramp-in, the joint-limit margin, the gripper-fault hold,
glitch holds, and velocities estimated from positions the same way in the node and the
environment."""
import dataclasses

import numpy as np
import pytest

from fr5_rl.config import ConfigError, load_yaml, typed
from fr5_rl.deploy.deployment import Command, Hold, HoldReason, StepInputs
from fr5_rl.deploy.joint_state import JointStateReader
from fr5_rl.motion_guard import MotionGuardSettings, StartPhase
from fr5_rl.envs import FR5Env
from fr5_rl.deploy.deployment import DeploymentStep
from fr5_rl.deploy.joint_state import Reading
from test_deployment import DT, ENV_CFG, NOW, ROBOT, TARGET, FixedPolicy, joint_reading, make_step

GUARD = typed(MotionGuardSettings, load_yaml("policy_node")["guard"], "policy_node.yaml guard")
HOME = np.asarray(ROBOT.home_joint_positions, dtype=float)
SPREAD = ENV_CFG.reach.start_joint_noise


def guarded(go_to_start=True, **changes) -> DeploymentStep:
    return make_step(guard=dataclasses.replace(GUARD, go_to_start=go_to_start, **changes))


def at(positions, now=NOW, fault=None) -> StepInputs:
    return StepInputs(now, joint_reading(positions, received=now), Reading(TARGET, now), gripper_fault=fault)


def test_bad_guard_settings_are_refused():
    with pytest.raises(ConfigError, match="at most 0.3"):
        typed(MotionGuardSettings, {**dataclasses.asdict(GUARD), "start_speed": 0.5}, "x")
    with pytest.raises(ConfigError, match="glitch_speed_factor"):
        typed(MotionGuardSettings, {**dataclasses.asdict(GUARD), "glitch_speed_factor": 1.0}, "x")


def test_inside_the_start_distribution_the_policy_runs_at_once():
    step = guarded(go_to_start=False)
    result = step(at(HOME + 0.9 * SPREAD))
    assert isinstance(result, Command) and result.target_in_base == TARGET
    assert step.guard.phase is StartPhase.RUNNING


def test_far_from_the_start_it_refuses_with_the_distance_until_the_move_is_asked_for():
    step = guarded(go_to_start=False)
    far = HOME.copy()
    far[2] += 0.6
    result = step(at(far))
    assert isinstance(result, Hold) and result.reason is HoldReason.FAR_FROM_START
    assert "0.600 rad" in result.detail and "j3" in result.detail and "~go_to_start" in result.detail
    step.guard.go_to_start_asked = True
    assert isinstance(step(at(far)), Command)  # asked once: the move starts


def test_the_start_move_is_slow_synchronised_and_hands_over_at_home():
    step = guarded(go_to_start=True)
    positions = HOME + np.array([0.5, -0.3, 0.2, 0.0, 0.1, -0.4])
    commands = []
    for period in range(400):
        result = step(at(positions, NOW + period * DT))
        assert isinstance(result, Command), result
        if result.target_in_base is not None:
            break  # the policy has the arm
        commands.append(np.asarray(result.arm_positions))
        assert result.gripper_width == ROBOT.max_opening_width  # open, as an episode starts
        positions = commands[-1]  # a perfectly tracking arm
    else:
        pytest.fail("the start move never handed over")
    steps = np.abs(np.diff(np.vstack([HOME + np.array([0.5, -0.3, 0.2, 0.0, 0.1, -0.4])] + commands), axis=0))
    assert steps.max() <= GUARD.start_speed * DT + 1e-12
    # Every joint arrives together: one straight line in joint space, the farthest joint at full speed.
    first = steps[0] / steps[0].max()
    np.testing.assert_allclose(first, np.array([0.5, 0.3, 0.2, 0.0, 0.1, 0.4]) / 0.5, atol=1e-9)
    assert len(commands) == pytest.approx((0.5 - GUARD.start_arrival) / (GUARD.start_speed * DT), abs=1)
    assert np.abs(positions - HOME).max() <= GUARD.start_arrival


def test_the_start_move_waits_at_home_until_the_arm_is_at_rest():
    """Exactly at the start pose but still moving (velocities estimated from positions lag one
    sample behind the last step): stand there until it settles, then hand over (this divided by
    a distance of 0 and stopped the node's timer)."""
    step = guarded(go_to_start=True)
    away = HOME + np.array([0.4, 0.0, 0.0, 0.0, 0.0, 0.0])
    assert step(at(away, NOW)).target_in_base is None  # the start move begins
    moving = StepInputs(NOW + DT, joint_reading(HOME, received=NOW + DT, velocities=[0.3, 0, 0, 0, 0, 0]),
                        Reading(TARGET, NOW + DT))
    standing = step(moving)
    assert isinstance(standing, Command) and standing.target_in_base is None
    np.testing.assert_allclose(standing.arm_positions, HOME)
    handed_over = step(at(HOME, NOW + 2 * DT))
    assert isinstance(handed_over, Command) and handed_over.target_in_base is not None


def test_an_unsafe_start_move_is_held():
    step = guarded(go_to_start=True)
    into_table = HOME.copy()
    into_table[1] = ROBOT.lower_limits[1] - 0.01  # beyond the limit: no target near it passes the gate
    result = step(at(into_table))
    assert isinstance(result, Hold) and result.reason is HoldReason.UNSAFE_COMMAND and "start move" in result.detail


def test_the_velocity_limit_ramps_in_after_a_hold():
    step = guarded()
    limit = ROBOT.velocity_limits * DT
    first = step(at(HOME, NOW))
    assert isinstance(first, Command)
    np.testing.assert_array_less(np.abs(np.subtract(first.arm_positions, HOME)), limit * DT / GUARD.ramp_time + 1e-12)
    unguarded = make_step()(at(HOME, NOW))
    assert np.abs(np.subtract(unguarded.arm_positions, HOME)).max() > limit.min() * DT / GUARD.ramp_time  # it binds
    # Well after the ramp the policy's own step passes unchanged; a hold starts it over.
    later = step(at(HOME, NOW + GUARD.ramp_time + DT))
    free = make_step()
    free(at(HOME, NOW))
    np.testing.assert_allclose(later.arm_positions, free(at(HOME, NOW + GUARD.ramp_time + DT)).arm_positions, atol=1e-12)
    assert isinstance(step(StepInputs(NOW + 1.0, None, Reading(TARGET, NOW + 1.0))), Hold)
    again = step(at(HOME, NOW + 1.02))
    np.testing.assert_array_less(np.abs(np.subtract(again.arm_positions, HOME)), limit * DT / GUARD.ramp_time + 1e-12)


def test_targets_keep_the_joint_limit_margin():
    """The fixed policy pushes j1 up, toward its upper limit."""
    for start, most in ((ROBOT.upper_limits[0] - GUARD.joint_limit_margin - 0.001, ROBOT.upper_limits[0] - GUARD.joint_limit_margin),
                        (ROBOT.upper_limits[0] - GUARD.joint_limit_margin / 2, None)):  # already inside the margin
        step = guarded(ramp_time=1e-6)
        step.guard.phase = StartPhase.RUNNING  # placed there by hand, not a training start
        near = HOME.copy()
        near[0] = start
        result = step(at(near))
        assert isinstance(result, Command)
        assert result.arm_positions[0] == pytest.approx(most if most is not None else start)  # stays, or stops at the margin
        assert make_step()(at(near)).arm_positions[0] > result.arm_positions[0]  # without the guard it goes on


def test_a_gripper_fault_holds():
    step = guarded()
    result = step(at(HOME, fault="/fr5/gripper/fault is true"))
    assert isinstance(result, Hold) and result.reason is HoldReason.GRIPPER_FAULT
    assert isinstance(step(at(HOME, NOW + DT)), Command)


def test_enabling_looks_at_the_start_again():
    step = guarded(go_to_start=False)
    assert isinstance(step(at(HOME)), Command)
    step.enabled = False
    far = HOME + 0.5
    assert step(at(far)).reason is HoldReason.DISABLED
    step.enabled = True
    assert step(at(far)).reason is HoldReason.FAR_FROM_START


# ----------------------------------------------------------------------------- the reader
ARM = list(ROBOT.joint_names)


def glitch_reader() -> JointStateReader:
    return JointStateReader(ROBOT.joint_names, ROBOT.finger_joint_names,
                            max_joint_speeds=ROBOT.velocity_limits * GUARD.glitch_speed_factor)


def test_a_one_message_spike_recovers_by_itself():
    joints = glitch_reader()
    joints.update(ARM, list(HOME), [0.0] * 6, 10.000, NOW)
    assert joints.reading().problem is None
    joints.update(ARM, list(HOME + 0.3), [0.0] * 6, 10.005, NOW + 0.005)  # 60 rad/s: no real motion
    assert "no real motion" in joints.reading().problem and joints.latched_jump() is not None
    joints.update(ARM, list(HOME + 0.001), [0.0] * 6, 10.010, NOW + 0.010)  # back, but a jump from the spike
    assert joints.reading().value is None
    joints.update(ARM, list(HOME + 0.002), [0.0] * 6, 10.015, NOW + 0.015)  # back, and agrees with the one before
    reading = joints.reading()
    assert reading.problem is None and reading.value.positions[0] == pytest.approx(HOME[0] + 0.002)
    assert joints.latched_jump() is None


def test_a_driver_glitching_every_other_message_stays_held():
    joints = glitch_reader()
    joints.update(ARM, list(HOME), [0.0] * 6, 10.000, NOW)
    for k in range(1, 101):
        joints.update(ARM, list(HOME + (0.3 if k % 2 else 0.0)), [0.0] * 6, 10.0 + 0.01 * k, NOW + 0.01 * k)
        assert joints.reading().value is None, f"commanded between glitches after {k} messages"


def test_a_jump_that_stays_latches_until_the_state_comes_back_or_an_operator_accepts_it():
    """The external fuzz run's fault: every joint 0.3 rad off, and it stays. Two states agree from
    the second message on; what is held is the jump from the last state that could be trusted."""
    joints = glitch_reader()
    joints.update(ARM, list(HOME), [0.0] * 6, 10.000, NOW)
    for k in range(1, 201):  # 1 s of a 200 Hz driver, all at the jumped value
        joints.update(ARM, list(HOME + 0.3), [0.0] * 6, 10.0 + 0.005 * k, NOW + 0.005 * k)
        assert joints.reading().value is None, f"commanded from the jumped state after {k} messages"
    assert "latched" in joints.reading().problem
    # Back near the trusted state (what the arm could have moved on its last command): clears.
    joints.update(ARM, list(HOME + 0.05), [0.0] * 6, 11.005, NOW + 1.005)
    joints.update(ARM, list(HOME + 0.05), [0.0] * 6, 11.010, NOW + 1.010)
    assert joints.reading().value is not None
    # A new jump that stays; ~enable (an operator who looked at the arm) accepts it.
    joints.update(ARM, list(HOME + 0.4), [0.0] * 6, 11.015, NOW + 1.015)
    joints.update(ARM, list(HOME + 0.4), [0.0] * 6, 11.020, NOW + 1.020)
    assert joints.reading().value is None
    assert "no real motion" in joints.accept_current()
    assert joints.reading().value.positions[0] == pytest.approx(HOME[0] + 0.4)
    joints.update(ARM, list(HOME + 0.41), [0.0] * 6, 11.025, NOW + 1.025)  # real motion from there on
    assert joints.reading().problem is None and joints.accept_current() is None


def test_a_latched_jump_is_not_cleared_by_joints_it_was_not_about_or_by_half_a_return():
    joints = glitch_reader()
    joints.update(ARM, list(HOME), [0.0] * 6, 10.000, NOW)
    jumped = HOME.copy()
    jumped[2] += 0.3
    joints.update(ARM, list(jumped), [0.0] * 6, 10.005, NOW + 0.005)
    joints.update(list(ROBOT.finger_joint_names), [0.02, 0.02], [0.0, 0.0], 10.010, NOW + 0.010)
    assert joints.reading().value is None  # a gripper's message says nothing about j3
    joints.update(ARM[:2], list(HOME[:2]), [0.0] * 2, 10.015, NOW + 0.015)  # a driver split in two: j1, j2 only
    assert joints.reading().value is None
    joints.update(ARM[2:], list(HOME[2:]), [0.0] * 4, 10.020, NOW + 0.020)  # j3..j6 back ...
    assert joints.reading().value is None
    joints.update(ARM[2:], list(HOME[2:]), [0.0] * 4, 10.025, NOW + 0.025)  # ... and agreeing
    assert joints.reading().value is not None


def test_fast_real_motion_and_repeated_messages_are_no_glitch():
    joints = glitch_reader()
    joints.update(ARM, list(HOME), [0.0] * 6, 10.00, NOW)
    joints.update(ARM, list(HOME + 0.06), [0.0] * 6, 10.02, NOW + 0.02)  # 3 rad/s: fast, possible
    joints.update(ARM, list(HOME + 0.06), [0.0] * 6, 10.02, NOW + 0.021)  # the same message twice
    assert joints.reading().problem is None
    joints.update(ARM, list(HOME + 0.07), [0.0] * 6, 10.02, NOW + 0.022)  # other values, same stamp
    assert "within one stamp" in joints.reading().problem


def test_velocities_from_positions_ignore_the_drivers_zeros():
    joints = JointStateReader(ROBOT.joint_names, (), velocities_from_positions=True)
    joints.update(ARM, list(HOME), [0.0] * 6, 1.00, NOW)
    joints.update(ARM, list(HOME + 0.01), [0.0] * 6, 1.02, NOW + 0.02)
    np.testing.assert_allclose(joints.reading().value.velocities, 0.5, atol=1e-9)
    trusting = JointStateReader(ROBOT.joint_names, ())
    trusting.update(ARM, list(HOME), [0.0] * 6, 1.00, NOW)
    trusting.update(ARM, list(HOME + 0.01), [0.0] * 6, 1.02, NOW + 0.02)
    np.testing.assert_allclose(trusting.reading().value.velocities, 0.0)


def test_the_node_estimates_velocities_as_the_environment_does():
    """The environment with joint_velocity_source: positions, and the deployment step fed the
    same 50 Hz joint states with zero velocities (as the FAIRINO driver sends them), observe the
    same velocities, period after period."""
    env = FR5Env("reach", config={"observation": {"joint_velocity_source": "positions"}})
    policy = FixedPolicy(np.zeros(7))
    step = DeploymentStep(policy, ROBOT, env.cfg, joint_state_timeout=0.1, target_timeout=0.5)
    reader = JointStateReader(ROBOT.joint_names, ROBOT.finger_joint_names, velocities_from_positions=True)
    rng = np.random.default_rng(3)
    moving = 0
    try:
        observation, _ = env.reset(seed=11)
        for period in range(30):
            states = env.episode.joint_states()
            stamp = 1.0 + period * DT
            reader.update(states.names, states.positions, [0.0] * len(states.names), stamp, stamp)
            assert isinstance(step(StepInputs(stamp, reader.reading(), Reading(tuple(env.object_position()), stamp))),
                              Command)
            np.testing.assert_allclose(policy.seen[-1][6:12], observation[6:12], atol=1e-6)
            moving += np.abs(observation[6:12]).max() > 0.01
            observation, *_ = env.step(rng.uniform(-1, 1, 7))
    finally:
        env.close()
    assert moving > 20  # the comparison saw the arm move
