"""Pure-logic unit tests of the code the simulator and the ROS policy node share.

``fr5_rl.observation.ObservationBuilder`` (observation layout and normalisation) and
``fr5_rl.control.JointCommandShaper`` (action -> safe joint targets). No simulator needed:
the expected numbers are computed here from the layout documented in observation.py and
control.py, so a change of index, scale or clamping shows up as a failure.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from fr5_rl.config import ConfigError, load_robot_spec
from fr5_rl.env_config import JointStepHintConfig, load_env_config
from fr5_rl.control import ACTION_SIZE, JointCommandShaper, pointing_down, yaw_of_rotation
from fr5_rl.kinematics import ForwardKinematics
from fr5_rl.observation import (
    GRASP_OBSERVATION_SIZE,
    REACH_OBSERVATION_SIZE,
    ObservationBuilder,
    ObservationInputs,
)

SPEC = load_robot_spec()
CFG = load_env_config()
CONTROL_DT = CFG.simulation.control_dt
MAX_WIDTH = SPEC.max_opening_width
REL_SCALE = CFG.observation.relative_position_scale
LIFT_SCALE = CFG.observation.lift_scale
TCP_LOW = np.asarray(CFG.observation.tcp_position_low, dtype=float)
TCP_HIGH = np.asarray(CFG.observation.tcp_position_high, dtype=float)
DOWN = np.diag([1.0, -1.0, -1.0])  # tcp z axis pointing straight down


def inputs(**changes) -> ObservationInputs:
    """A neutral observation input: joints at mid-range, at rest, tcp at the box centre."""
    base = dict(
        joint_positions=(SPEC.lower_limits + SPEC.upper_limits) / 2.0,
        joint_velocities=np.zeros(6),
        gripper_width=MAX_WIDTH / 2.0,
        gripper_command_width=MAX_WIDTH / 2.0,
        tcp_position=(TCP_LOW + TCP_HIGH) / 2.0,
        tcp_approach_axis=DOWN[:, 2].copy(),
        object_position=(TCP_LOW + TCP_HIGH) / 2.0,
        object_lift=0.0,
    )
    base.update(changes)
    return ObservationInputs(**base)


@pytest.fixture
def reach_builder():
    return ObservationBuilder(SPEC, CFG.observation, include_lift=False)


@pytest.fixture
def grasp_builder():
    return ObservationBuilder(SPEC, CFG.observation, include_lift=True)


# ----------------------------------------------------------------------------- observation
def test_sizes(reach_builder, grasp_builder):
    assert reach_builder.size == REACH_OBSERVATION_SIZE == 23
    assert grasp_builder.size == GRASP_OBSERVATION_SIZE == 24
    assert reach_builder.build(inputs()).shape == (23,)
    obs = grasp_builder.build(inputs())
    assert obs.shape == (24,) and obs.dtype == np.float32


def test_neutral_input_maps_to_zero_except_orientation(reach_builder):
    obs = reach_builder.build(inputs())
    expected = np.zeros(23)
    expected[17:20] = DOWN[:, 2]  # approach axis (0, 0, -1)
    np.testing.assert_allclose(obs, expected, atol=1e-6)


@pytest.mark.parametrize("joint", range(6))
def test_joint_limits_map_to_plus_minus_one(reach_builder, joint):
    q = (SPEC.lower_limits + SPEC.upper_limits) / 2.0
    q[joint] = SPEC.upper_limits[joint]
    obs = reach_builder.build(inputs(joint_positions=q))
    assert obs[joint] == pytest.approx(1.0, abs=1e-6)
    others = [i for i in range(6) if i != joint]
    np.testing.assert_allclose(obs[others], 0.0, atol=1e-6)
    q[joint] = SPEC.lower_limits[joint]
    assert reach_builder.build(inputs(joint_positions=q))[joint] == pytest.approx(-1.0, abs=1e-6)
    # A quarter of the range above the lower limit maps to -0.5.
    q[joint] = SPEC.lower_limits[joint] + 0.25 * (SPEC.upper_limits[joint] - SPEC.lower_limits[joint])
    assert reach_builder.build(inputs(joint_positions=q))[joint] == pytest.approx(-0.5, abs=1e-6)


def test_joint_velocities_scaled_by_velocity_limits(reach_builder):
    qd = SPEC.velocity_limits * np.array([1.0, -1.0, 0.5, -0.5, 0.25, 0.0])
    obs = reach_builder.build(inputs(joint_velocities=qd))
    np.testing.assert_allclose(obs[6:12], [1.0, -1.0, 0.5, -0.5, 0.25, 0.0], atol=1e-6)
    np.testing.assert_allclose(obs[0:6], 0.0, atol=1e-6)


def test_gripper_widths(reach_builder):
    obs = reach_builder.build(inputs(gripper_width=MAX_WIDTH, gripper_command_width=0.0))
    assert obs[12] == pytest.approx(1.0) and obs[13] == pytest.approx(-1.0)
    obs = reach_builder.build(inputs(gripper_width=0.0, gripper_command_width=MAX_WIDTH))
    assert obs[12] == pytest.approx(-1.0) and obs[13] == pytest.approx(1.0)


def test_tcp_position_box(reach_builder):
    obs = reach_builder.build(inputs(tcp_position=TCP_HIGH.copy(), object_position=TCP_HIGH.copy()))
    np.testing.assert_allclose(obs[14:17], 1.0, atol=1e-6)
    obs = reach_builder.build(inputs(tcp_position=TCP_LOW.copy(), object_position=TCP_LOW.copy()))
    np.testing.assert_allclose(obs[14:17], -1.0, atol=1e-6)


def test_approach_axis_is_third_rotation_column(reach_builder):
    angle = 0.3
    c, s = np.cos(angle), np.sin(angle)
    rotation = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]]) @ DOWN
    obs = reach_builder.build(inputs(tcp_approach_axis=rotation[:, 2]))
    np.testing.assert_allclose(obs[17:20], rotation[:, 2], atol=1e-6)


@pytest.mark.parametrize("axis", range(3))
def test_object_offset_indices(reach_builder, axis):
    tcp = np.array([-0.5, 0.1, 0.3])
    for distance, expected in ((REL_SCALE, 1.0), (-REL_SCALE, -1.0), (REL_SCALE / 4, 0.25),
                               (2.0 * REL_SCALE, 1.0)):  # beyond the scale: clamped
        obj = tcp.copy()
        obj[axis] += distance
        obs = reach_builder.build(inputs(tcp_position=tcp, object_position=obj))
        assert obs[20 + axis] == pytest.approx(expected, abs=1e-6), (axis, distance)
        others = [20 + i for i in range(3) if i != axis]
        np.testing.assert_allclose(obs[others], 0.0, atol=1e-6)


def test_object_0_8m_beyond_tcp_is_plus_one(reach_builder):
    tcp = np.array([-0.4, 0.0, 0.2])
    obs = reach_builder.build(inputs(tcp_position=tcp, object_position=tcp + 0.8))
    np.testing.assert_allclose(obs[20:23], 1.0, atol=1e-6)


def test_lift_only_in_grasp(reach_builder, grasp_builder):
    obs = grasp_builder.build(inputs(object_lift=LIFT_SCALE / 2.0))
    assert obs[23] == pytest.approx(0.5)
    assert grasp_builder.build(inputs(object_lift=LIFT_SCALE))[23] == pytest.approx(1.0)
    assert grasp_builder.build(inputs(object_lift=10.0))[23] == pytest.approx(1.0)
    np.testing.assert_allclose(reach_builder.build(inputs(object_lift=0.1)), obs[:23], atol=1e-6)


def test_outputs_clamped_to_unit_box(grasp_builder):
    rng = np.random.default_rng(0)
    for _ in range(200):
        obs = grasp_builder.build(inputs(
            joint_positions=rng.uniform(-10, 10, 6), joint_velocities=rng.uniform(-50, 50, 6),
            gripper_width=rng.uniform(-1, 1), gripper_command_width=rng.uniform(-1, 1),
            tcp_position=rng.uniform(-5, 5, 3), object_position=rng.uniform(-5, 5, 3),
            object_lift=rng.uniform(-2, 2)))
        assert np.all(obs >= -1.0) and np.all(obs <= 1.0)
        assert np.any(np.abs(obs) == 1.0)  # something was out of range and got clamped


@pytest.mark.parametrize("field,value", [
    ("joint_positions", np.array([0.0, np.nan, 0.0, 0.0, 0.0, 0.0])),
    ("joint_velocities", np.array([np.inf, 0.0, 0.0, 0.0, 0.0, 0.0])),
    ("gripper_width", float("nan")),
    ("tcp_position", np.array([0.0, 0.0, np.nan])),
    ("object_position", np.array([np.nan, 0.0, 0.0])),
    ("object_lift", float("-inf")),
])
def test_non_finite_input_raises(grasp_builder, field, value):
    with pytest.raises(ValueError):
        grasp_builder.build(inputs(**{field: value}))


@pytest.mark.parametrize("field,value", [
    ("joint_positions", np.zeros((6, 1))), ("joint_positions", [None] * 6), ("joint_velocities", np.zeros(5)),
    ("tcp_position", np.zeros((3, 2))), ("tcp_position", 0.5), ("tcp_position", np.zeros(4)),
    ("tcp_approach_axis", np.zeros(2)), ("object_position", "abc"), ("gripper_width", "x"),
], ids=["q 6x1", "q None", "qd 5", "tcp 3x2", "tcp scalar", "tcp 4", "axis 2", "object str", "width str"])
def test_malformed_input_raises_value_error(grasp_builder, field, value):
    """The policy node holds on ValueError; nothing malformed may escape as another error."""
    with pytest.raises(ValueError):
        grasp_builder.build(inputs(**{field: value}))


def test_out_buffer_is_used(reach_builder):
    out = np.full(23, 7.0, dtype=np.float32)
    result = reach_builder.build(inputs(), out=out)
    assert result is out and np.all(np.abs(out) <= 1.0)


# ----------------------------------------------------------------------------- control
def shaper(max_joint_step=None, alpha=None) -> JointCommandShaper:
    cfg = CFG.action
    if max_joint_step is not None:
        cfg = dataclasses.replace(cfg, max_joint_step=max_joint_step)
    if alpha is not None:
        cfg = dataclasses.replace(cfg, smoothing_alpha=alpha)
    return JointCommandShaper(SPEC, cfg, CONTROL_DT)


MID = (SPEC.lower_limits + SPEC.upper_limits) / 2.0


def action(joint_values, gripper=0.0) -> np.ndarray:
    a = np.zeros(ACTION_SIZE)
    a[:6] = joint_values
    a[6] = gripper
    return a


def test_first_step_is_alpha_times_max_step():
    s = shaper(max_joint_step=0.04, alpha=0.7)
    targets = s.arm_targets(action([1, -1, 0.5, 0, 0, 0]), MID)
    np.testing.assert_allclose(targets - MID, 0.7 * 0.04 * np.array([1, -1, 0.5, 0, 0, 0]), atol=1e-12)


def test_low_pass_filter_sequence_and_reset():
    alpha, max_step = 0.7, 0.04
    s = shaper(max_joint_step=max_step, alpha=alpha)
    expected = np.zeros(6)
    for k in range(12):
        raw = max_step * np.array([1.0, -1.0, 0.0, 0.5, 1.0, -0.2])
        expected = alpha * raw + (1 - alpha) * expected
        step = s.arm_targets(action(raw / max_step), MID) - MID
        np.testing.assert_allclose(step, expected, atol=1e-12, err_msg=f"step {k}")
    # Converges to the unfiltered step.
    np.testing.assert_allclose(step, raw, atol=max_step * (1 - alpha) ** 12 + 1e-12)
    # A zero action decays geometrically rather than stopping at once.
    decayed = s.arm_targets(action(np.zeros(6)), MID) - MID
    np.testing.assert_allclose(decayed, (1 - alpha) * expected, atol=1e-12)
    s.reset()
    np.testing.assert_allclose(s.arm_targets(action(np.zeros(6)), MID), MID, atol=1e-12)


def test_alpha_one_means_no_filter():
    s = shaper(alpha=1.0)
    max_step = CFG.action.max_joint_step
    s.arm_targets(action(np.ones(6)), MID)
    np.testing.assert_allclose(s.arm_targets(action(-np.ones(6)), MID) - MID, -max_step, atol=1e-12)


def test_increments_apply_to_measured_position():
    s = shaper(alpha=1.0)
    max_step = CFG.action.max_joint_step
    measured = MID + np.array([0.1, -0.2, 0.3, 0.0, 0.05, -0.05])
    np.testing.assert_allclose(s.arm_targets(action(np.ones(6) * 0.5), measured),
                               measured + 0.5 * max_step, atol=1e-12)


def test_clamped_at_joint_limits():
    s = shaper(alpha=1.0)
    np.testing.assert_array_equal(s.arm_targets(action(np.ones(6)), SPEC.upper_limits), SPEC.upper_limits)
    np.testing.assert_array_equal(s.arm_targets(action(-np.ones(6)), SPEC.lower_limits), SPEC.lower_limits)
    near = SPEC.upper_limits - 0.001
    np.testing.assert_array_equal(s.arm_targets(action(np.ones(6)), near), SPEC.upper_limits)
    # Measured slightly past a limit (overshoot): the target comes back inside.
    past = SPEC.upper_limits + 0.01
    assert np.all(s.arm_targets(action(np.ones(6)), past) <= SPEC.upper_limits)


def test_actions_beyond_one_are_clipped():
    max_step = CFG.action.max_joint_step
    a, b = shaper(alpha=1.0), shaper(alpha=1.0)
    np.testing.assert_array_equal(a.arm_targets(action(10 * np.array([1, -1, 1, -1, 1, -1])), MID),
                                  b.arm_targets(action(np.array([1, -1, 1, -1, 1, -1])), MID))
    assert np.max(np.abs(a.arm_targets(action(np.full(6, 1e6)), MID) - MID)) <= max_step + 1e-12


def test_rate_limit_even_if_max_step_too_large():
    """The shaper itself caps the increment at velocity_limit * control_dt (defence in depth)."""
    s = shaper(max_joint_step=1.0, alpha=1.0)
    step = s.arm_targets(action(np.array([1, -1, 1, -1, 1, -1])), MID) - MID
    np.testing.assert_allclose(np.abs(step), SPEC.velocity_limits * CONTROL_DT, atol=1e-12)


def test_random_targets_respect_limits():
    rng = np.random.default_rng(1)
    s = shaper()
    step_limit = SPEC.velocity_limits * CONTROL_DT
    for _ in range(2000):
        measured = rng.uniform(SPEC.lower_limits - 0.05, SPEC.upper_limits + 0.05)
        targets = s.arm_targets(rng.uniform(-10, 10, ACTION_SIZE), measured)
        assert np.all(targets >= SPEC.lower_limits) and np.all(targets <= SPEC.upper_limits)
        inside = (measured >= SPEC.lower_limits) & (measured <= SPEC.upper_limits)
        assert np.all(np.abs(targets - measured)[inside] <= step_limit[inside] + 1e-12)


@pytest.mark.parametrize("bad", [
    action([np.nan, 0, 0, 0, 0, 0]), action([0, 0, np.inf, 0, 0, 0]), action(np.zeros(6), np.nan)])
def test_shaper_non_finite_action_raises(bad):
    with pytest.raises(ValueError):
        shaper().arm_targets(bad, MID)


def test_shaper_non_finite_measurement_raises():
    measured = MID.copy()
    measured[3] = np.nan
    with pytest.raises(ValueError):
        shaper().arm_targets(action(np.zeros(6)), measured)


@pytest.mark.parametrize("bad_action,bad_measured", [
    (np.zeros(6), MID), (np.zeros(8), MID), (np.zeros(7), MID[:5]), (np.zeros(7), np.zeros((6, 2))),
    ([None] * 7, MID), (["a"] * 7, MID), ([[0.1]] * 7, MID), ([0.1] * 7, [None] * 6), ([0.1] * 6, MID),
    (np.array(["a"] * 7), MID)])
def test_shaper_wrong_shapes_raise(bad_action, bad_measured):
    with pytest.raises(ValueError):
        shaper().arm_targets(bad_action, bad_measured)


def test_gripper_width_mapping():
    s = shaper()
    assert s.gripper_width(action(np.zeros(6), -1.0)) == pytest.approx(0.0)
    assert s.gripper_width(action(np.zeros(6), 1.0)) == pytest.approx(MAX_WIDTH)
    assert s.gripper_width(action(np.zeros(6), 0.0)) == pytest.approx(MAX_WIDTH / 2)
    assert s.gripper_width(action(np.zeros(6), 10.0)) == pytest.approx(MAX_WIDTH)
    assert s.gripper_width(action(np.zeros(6), -10.0)) == pytest.approx(0.0)
    for width in np.linspace(0.0, MAX_WIDTH, 9):
        assert s.gripper_width(action(np.zeros(6), s.gripper_action(width))) == pytest.approx(width)
    with pytest.raises(ValueError):
        s.gripper_width(action(np.zeros(6), np.nan))


# ----------------------------------------------------------------------------- previous actions
def history_builder(count: int, include_lift: bool = True) -> ObservationBuilder:
    return ObservationBuilder(SPEC, dataclasses.replace(CFG.observation, previous_actions=count), include_lift=include_lift)


def test_previous_actions_come_last_newest_first_and_clipped():
    from fr5_rl.observation import ActionHistory, observation_size

    builder = history_builder(2)
    assert builder.size == GRASP_OBSERVATION_SIZE + 12 == observation_size("grasp", dataclasses.replace(CFG.observation, previous_actions=2))
    history = ActionHistory(2)
    assert history.values() == [0.0] * 12  # an episode starts at rest
    history.push([0.1, 0.2, 0.3, 0.4, 0.5, 0.6, -1.0])  # the gripper value is not kept
    history.push([2.0, -3.0, 0.0, 0.0, 0.0, -0.5, 1.0])  # out of range: clipped, as the env clips
    plain = history_builder(0).build(inputs(object_lift=0.01))
    observation = builder.build(inputs(object_lift=0.01, previous_actions=history.values()))
    np.testing.assert_allclose(observation[:GRASP_OBSERVATION_SIZE], plain)
    np.testing.assert_allclose(observation[GRASP_OBSERVATION_SIZE:],
                               [1.0, -1.0, 0, 0, 0, -0.5, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6], atol=1e-7)
    history.push([0.0] * 7)
    history.push([0.0] * 7)
    assert history.values() == [0.0] * 12  # only the last two are kept
    history.push([0.3] * 7)
    history.reset()
    assert history.values() == [0.0] * 12


@pytest.mark.parametrize("bad", [[0.0] * 11, [0.0] * 13, [0.0] * 11 + [float("nan")], [0.0] * 11 + ["x"]],
                         ids=["short", "long", "nan", "text"])
def test_previous_actions_of_the_wrong_length_or_not_finite_are_refused(bad):
    with pytest.raises(ValueError, match="previous-action|NaN|numbers"):
        history_builder(2).build(inputs(previous_actions=bad))


def test_a_builder_without_previous_actions_refuses_some():
    """A model trained without the block never gets one (or the other way round) silently."""
    with pytest.raises(ValueError, match="0 previous-action values"):
        history_builder(0).build(inputs(previous_actions=[0.0] * 6))
    with pytest.raises(ValueError, match="6 previous-action values"):
        history_builder(1).build(inputs())


# ----------------------------------------------------------------------------- joint-step hint
HINT = {"cartesian_step": 0.015, "rotation_step": 0.05, "damping": 0.05, "joint_step_scale": 0.04}
# A pose from which the tcp can move every way: elbow bent, wrist pointing roughly down.
BENT = np.array([0.3, -1.2, 1.6, -2.0, -1.5, 0.2])


def hint_builder(include_lift: bool = False, **changes) -> ObservationBuilder:
    return ObservationBuilder(SPEC, dataclasses.replace(CFG.observation, joint_step_hint=JointStepHintConfig(**{**HINT, **changes})),
                              include_lift)


def test_tcp_jacobian_matches_finite_differences_of_the_tcp_pose():
    from fr5_rl.kinematics import ForwardKinematics

    kinematics = ForwardKinematics(SPEC)
    for q in np.random.default_rng(3).uniform(SPEC.lower_limits / 2, SPEC.upper_limits / 2, (5, 6)):
        position, axis, jacobian = kinematics.tcp_jacobian(q.tolist())
        position_now, rotation_now = kinematics.tcp_pose(q)
        np.testing.assert_allclose(position, position_now, atol=1e-12)
        np.testing.assert_allclose(axis, rotation_now[:, 2], atol=1e-12)
        jacobian, eps = np.array(jacobian), 1e-7
        for joint in range(6):
            moved = q.copy()
            moved[joint] += eps
            position_moved, rotation_moved = kinematics.tcp_pose(moved)
            turn = (rotation_moved @ rotation_now.T - np.eye(3)) / eps  # skew matrix of the angular velocity
            np.testing.assert_allclose(jacobian[:3, joint], (position_moved - position_now) / eps, atol=1e-5)
            np.testing.assert_allclose(jacobian[3:, joint], [turn[2, 1], turn[0, 2], turn[1, 0]], atol=1e-5)



def test_inverse_kinematics_returns_joints_whose_tcp_pose_is_the_target():
    from fr5_rl.kinematics import ForwardKinematics, InverseKinematics

    kinematics = ForwardKinematics(SPEC)
    inverse = InverseKinematics(kinematics)
    rng = np.random.default_rng(11)
    for goal in rng.uniform(SPEC.lower_limits / 2, SPEC.upper_limits / 2, (20, 6)):
        position, rotation = kinematics.tcp_pose(goal)
        start = goal + rng.uniform(-0.05, 0.05, 6)  # a few centimetres away, as the expert asks
        joints, converged = inverse.solve(start.tolist(), position, rotation.ravel())
        assert converged
        reached_position, reached_rotation = kinematics.tcp_pose(np.array(joints))
        np.testing.assert_allclose(reached_position, position, atol=1e-6)
        np.testing.assert_allclose(reached_rotation, rotation, atol=1e-6)
        # Six joints, six constraints: the pose's solution nearest the start is the goal itself
        # (the other branches lie radians away; near a singular wrist, 1e-7 of pose is 1e-4 rad).
        np.testing.assert_allclose(joints, goal, atol=1e-3)


def test_inverse_kinematics_says_when_it_has_not_converged():
    from fr5_rl.kinematics import ForwardKinematics, InverseKinematics

    kinematics = ForwardKinematics(SPEC)
    goal = np.array(SPEC.home_joint_positions) + 0.4
    position, rotation = kinematics.tcp_pose(goal)
    start = list(SPEC.home_joint_positions)
    joints, converged = InverseKinematics(kinematics).solve(start, position, rotation.ravel(), max_iterations=1)
    assert not converged and joints != start  # one step taken toward it, and reported as such
    joints, converged = InverseKinematics(kinematics).solve(start, position, rotation.ravel())
    assert converged

def test_the_hint_comes_last_and_the_rest_is_unchanged():
    from fr5_rl.observation import observation_size

    for include_lift, task, base in ((False, "reach", REACH_OBSERVATION_SIZE), (True, "grasp", GRASP_OBSERVATION_SIZE)):
        builder = hint_builder(include_lift)
        assert builder.size == base + 6 == observation_size(task, dataclasses.replace(CFG.observation, joint_step_hint=JointStepHintConfig(**HINT)))
        state = inputs(joint_positions=BENT, object_position=np.array([-0.5, 0.1, 0.03]))
        observation = builder.build(state)
        np.testing.assert_allclose(observation[:base], ObservationBuilder(SPEC, CFG.observation, include_lift).build(state))
        np.testing.assert_allclose(observation[base:], builder.joint_step_hint(BENT, [-0.5, 0.1, 0.03]), atol=1e-7)
        assert np.all(np.abs(observation[base:]) <= 1.0)


@pytest.mark.parametrize("offset", [(0.3, 0.0, -0.2), (-0.1, 0.25, 0.05), (0.0, 0.0, -0.3), (0.008, -0.004, 0.002)])
def test_the_hinted_step_moves_the_tcp_toward_the_object(offset):
    """Far away the step moves the tcp about cartesian_step straight at the object (less where a
    joint's step is capped at joint_step_scale, the hint's +-1); within one step it closes most of
    the remaining offset."""
    from fr5_rl.kinematics import ForwardKinematics

    kinematics = ForwardKinematics(SPEC)
    builder = hint_builder(rotation_step=1e-6)  # position only, to measure it alone
    tcp, _ = kinematics.tcp_pose(BENT)
    target = tcp + np.asarray(offset)
    hint = np.asarray(builder.joint_step_hint(BENT, target))
    step = hint * HINT["joint_step_scale"]
    moved, _ = kinematics.tcp_pose(BENT + step)
    before, after = np.linalg.norm(target - tcp), np.linalg.norm(target - moved)
    if before > HINT["cartesian_step"]:
        if np.abs(hint).max() < 1.0:
            assert before - after == pytest.approx(HINT["cartesian_step"], abs=0.003)
        else:  # a joint at its cap: the tcp goes less far, the same way
            assert 0.3 * HINT["cartesian_step"] < before - after < HINT["cartesian_step"] + 0.003
        direction = (moved - tcp) / np.linalg.norm(moved - tcp)
        assert direction @ (target - tcp) / before > 0.98
    else:
        assert after < 0.3 * before


def test_the_hint_turns_the_approach_axis_toward_straight_down():
    from fr5_rl.kinematics import ForwardKinematics

    kinematics = ForwardKinematics(SPEC)
    builder = hint_builder(cartesian_step=1e-6)  # orientation only
    q = BENT + np.array([0.0, 0.0, 0.0, 0.4, 0.3, 0.0])  # wrist turned: about 30 degrees off down
    angles = []
    for _ in range(40):
        tcp, rotation = kinematics.tcp_pose(q)
        angles.append(np.degrees(np.arccos(np.clip(-rotation[2, 2], -1.0, 1.0))))  # rounding may leave it past 1
        q = q + np.asarray(builder.joint_step_hint(q, tcp)) * HINT["joint_step_scale"]
    assert angles[0] > 25.0 and angles[-1] < 0.5
    assert angles[0] - angles[1] == pytest.approx(np.degrees(HINT["rotation_step"]), abs=0.5)  # the capped turn
    # Every step turns it further down, up to rounding: near straight down arccos turns a
    # 1e-12 error in the rotation matrix into 1e-4 degrees.
    assert np.all(np.diff(angles) < 1e-3)


@pytest.mark.parametrize("bad", [{"cartesian_step": 0.015}, {**HINT, "extra": 1.0}, {**HINT, "damping": -0.05},
                                 {**HINT, "joint_step_scale": 0.0}, {**HINT, "rotation_step": "fast"},
                                 {**HINT, "cartesian_step": True}, {**HINT, "damping": float("inf")}, [0.015] * 4],
                         ids=["missing", "unknown", "negative", "zero", "text", "bool", "inf", "list"])
def test_a_malformed_hint_setting_is_refused(bad):
    from fr5_rl.config import ConfigError

    with pytest.raises(ConfigError, match="joint_step_hint"):
        load_env_config({"observation": {"joint_step_hint": bad}})


def test_a_model_whose_meta_lacks_an_observation_key_is_refused(tmp_path):
    """No reading of older files with guessed defaults: a meta.json without a key the code needs
    is named in one refusal (the shipped ones are all current)."""
    import json
    import shutil

    from fr5_rl.deploy.bundle import ModelFilesError
    from fr5_rl.deploy.policy import load_policy

    model = tmp_path / "reach"
    shutil.copytree(Path(__file__).resolve().parent.parent / "models" / "reach", model)
    meta = json.loads((model / "meta.json").read_text())
    del meta["env_config"]["observation"]["previous_actions"]
    (model / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(ModelFilesError, match="observation"):
        load_policy(model, backend="onnx")


def test_tcp_position_and_axis_is_tcp_pose_to_the_bit():
    """The env's noisy-observation path uses the float form; it must not change a single bit of
    what tcp_pose (numpy) gives, or seeded rollouts would change with the speed-up."""
    from fr5_rl.kinematics import ForwardKinematics

    kinematics = ForwardKinematics(SPEC)
    for q in np.random.default_rng(11).uniform(SPEC.lower_limits, SPEC.upper_limits, (50, 6)):
        position, axis = kinematics.tcp_position_and_axis(q.tolist())
        position_np, rotation_np = kinematics.tcp_pose(q)
        assert position == position_np.tolist()
        assert axis == rotation_np[:, 2].tolist()


def test_joint_step_hint_solves_the_damped_least_squares_system():
    """The hint's solve (numpy's kernel called directly) against the formula written out."""
    from fr5_rl.env_config import JointStepHintConfig
    from fr5_rl.kinematics import ForwardKinematics
    from fr5_rl.observation import JointStepHint

    settings = JointStepHintConfig(cartesian_step=0.015, rotation_step=0.05, damping=0.05, joint_step_scale=0.04)
    hint, kinematics = JointStepHint(SPEC, settings), ForwardKinematics(SPEC)
    rng = np.random.default_rng(12)
    for q in rng.uniform(SPEC.lower_limits / 2, SPEC.upper_limits / 2, (20, 6)):
        target = rng.uniform([-0.7, -0.4, 0.0], [-0.3, 0.4, 0.2])
        position, axis, jacobian = kinematics.tcp_jacobian(q.tolist())
        error = target - np.array(position)
        error *= min(1.0, 0.015 / np.linalg.norm(error))
        turn = np.array([-axis[1], axis[0]])
        turn *= min(1.0, 0.05 / max(np.linalg.norm(turn), 1e-300))
        wanted = np.concatenate([error, turn, [0.0]])
        jacobian = np.array(jacobian)
        step = jacobian.T @ np.linalg.inv(jacobian @ jacobian.T + 0.05 ** 2 * np.eye(6)) @ wanted / 0.04
        np.testing.assert_allclose(hint(q.tolist(), target.tolist()), np.clip(step, -1.0, 1.0), atol=1e-9)


def test_one_kinematic_chain_serves_the_noisy_tcp_pose_and_the_hint_bit_for_bit():
    """The environment computes tcp_jacobian once for a noisy observation and hands it to the
    hint: its tcp pose must equal tcp_position_and_axis's to the bit, and the hint given the
    chain must equal the hint computing it."""
    from fr5_rl.env_config import JointStepHintConfig
    from fr5_rl.kinematics import ForwardKinematics
    from fr5_rl.observation import JointStepHint

    settings = JointStepHintConfig(cartesian_step=0.015, rotation_step=0.05, damping=0.05, joint_step_scale=0.04)
    hint, kinematics = JointStepHint(SPEC, settings), ForwardKinematics(SPEC)
    rng = np.random.default_rng(21)
    for q in rng.uniform(SPEC.lower_limits, SPEC.upper_limits, (50, 6)).tolist():
        target = rng.uniform([-0.7, -0.4, 0.0], [-0.3, 0.4, 0.2]).tolist()
        chain = kinematics.tcp_jacobian(q)
        assert (chain[0], chain[1]) == kinematics.tcp_position_and_axis(q)
        assert hint(q, target, chain) == hint(q, target)


# ----------------------------------------------------------------------------- tcp-space actions
def tcp_shaper(alpha=1.0) -> JointCommandShaper:
    cfg = dataclasses.replace(CFG.action, space="tcp", smoothing_alpha=alpha)
    return JointCommandShaper(SPEC, cfg, CONTROL_DT)


KINEMATICS = ForwardKinematics(SPEC)
HOME = np.asarray(SPEC.home_joint_positions, dtype=float)


@pytest.mark.parametrize("translation", [[0.5, 0, 0], [0, -0.5, 0], [0, 0, 0.3], [-0.2, 0.4, -0.3]])
def test_tcp_action_moves_the_tcp_by_its_step(translation):
    """A translation-only tcp action moves the tcp by value x max_tcp_translation_step in
    base_link and leaves its rotation as it was."""
    position, rotation = KINEMATICS.tcp_pose(HOME)
    targets = tcp_shaper().arm_targets(action(translation + [0, 0, 0]), HOME)
    new_position, new_rotation = KINEMATICS.tcp_pose(targets)
    step = np.asarray(translation) * CFG.action.max_tcp_translation_step
    np.testing.assert_allclose(new_position - position, step, atol=2e-5)
    np.testing.assert_allclose(new_rotation, rotation, atol=1e-4)


def test_tcp_action_turns_the_tcp_about_base_z():
    """Value 5 turns the tcp's yaw by value x max_tcp_rotation_step, its position and approach
    axis kept."""
    position, rotation = KINEMATICS.tcp_pose(HOME)
    targets = tcp_shaper().arm_targets(action([0, 0, 0, 0, 0, 0.5]), HOME)
    new_position, new_rotation = KINEMATICS.tcp_pose(targets)
    turn = 0.5 * CFG.action.max_tcp_rotation_step
    expected = np.array([[np.cos(turn), -np.sin(turn), 0], [np.sin(turn), np.cos(turn), 0], [0, 0, 1]]) @ rotation
    np.testing.assert_allclose(new_rotation, expected, atol=1e-4)
    np.testing.assert_allclose(new_position, position, atol=2e-5)


def test_tcp_action_scaled_whole_to_one_joint_step():
    """A tcp step larger than one max_joint_step of some joint is shrunk whole: no joint moves
    more than max_joint_step, one nearly that, and the tcp keeps the step's direction."""
    cfg = dataclasses.replace(CFG.action, space="tcp", smoothing_alpha=1.0, max_tcp_translation_step=0.2)
    s = JointCommandShaper(SPEC, cfg, CONTROL_DT)
    position, _ = KINEMATICS.tcp_pose(HOME)
    targets = s.arm_targets(action([1, 0, 0, 0, 0, 0]), HOME)
    largest = np.max(np.abs(targets - HOME))
    assert 0.9 * CFG.action.max_joint_step <= largest <= CFG.action.max_joint_step + 1e-12
    moved = KINEMATICS.tcp_pose(targets)[0] - position
    assert moved[0] > 0.005 and np.hypot(moved[1], moved[2]) < 0.02 * moved[0]


def test_tcp_space_targets_respect_limits():
    rng = np.random.default_rng(2)
    s = tcp_shaper(alpha=CFG.action.smoothing_alpha)
    step_limit = SPEC.velocity_limits * CONTROL_DT
    for _ in range(300):
        measured = rng.uniform(SPEC.lower_limits, SPEC.upper_limits)
        targets = s.arm_targets(rng.uniform(-10, 10, ACTION_SIZE), measured)
        assert np.all(np.isfinite(targets))
        assert np.all(targets >= SPEC.lower_limits) and np.all(targets <= SPEC.upper_limits)
        assert np.all(np.abs(targets - measured) <= np.minimum(step_limit, CFG.action.max_joint_step) + 1e-12)


@pytest.mark.parametrize("yaw", [0.0, 0.7, -2.5, 3.1])
def test_pointing_down_has_the_yaw_it_is_given(yaw):
    rotation = np.asarray(pointing_down(yaw)).reshape(3, 3)
    np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(rotation) == pytest.approx(1.0)
    np.testing.assert_allclose(rotation[:, 2], [0.0, 0.0, -1.0])
    assert yaw_of_rotation(rotation.ravel()) == pytest.approx(yaw)


def test_tcp_space_ignores_the_tilt_values_and_rights_a_tilted_hand():
    """Values 3 and 4 do not tilt the hand; a hand tilted off straight down (the measured joints)
    is turned back toward it."""
    s = tcp_shaper()
    np.testing.assert_allclose(s.arm_targets(action([0, 0, 0, 1, -1, 0]), HOME), HOME, atol=1e-6)
    tilted = HOME + np.array([0, 0, 0, 0, 0.05, 0])
    axis_before = KINEMATICS.tcp_pose(tilted)[1][:, 2]
    targets = s.arm_targets(action(np.zeros(6)), tilted)
    axis_after = KINEMATICS.tcp_pose(targets)[1][:, 2]
    assert np.arccos(-axis_after[2]) < np.arccos(-axis_before[2]) - 0.01


def test_unknown_action_space_refused():
    with pytest.raises(ConfigError, match="action.space"):
        load_env_config({"action": {"space": "cartesian"}})


def test_open_close_gripper_opens_fully_above_zero_and_closes_otherwise():
    """``action.gripper: open_close``: the gripper's value says open (above 0: the whole stroke)
    or closed, nothing between; ``width`` maps it linearly onto the stroke."""
    open_close = JointCommandShaper(SPEC, dataclasses.replace(CFG.action, gripper="open_close"), CONTROL_DT)
    width = JointCommandShaper(SPEC, dataclasses.replace(CFG.action, gripper="width"), CONTROL_DT)
    for value, expected in ((0.6, MAX_WIDTH), (0.01, MAX_WIDTH), (0.0, 0.0), (-0.3, 0.0), (5.0, MAX_WIDTH)):
        assert open_close.gripper_width(action(np.zeros(6), value)) == expected, value
    assert width.gripper_width(action(np.zeros(6), 0.6)) == pytest.approx(0.8 * MAX_WIDTH)
    with pytest.raises(ValueError):
        open_close.gripper_width(action(np.zeros(6), np.nan))


def test_unknown_gripper_command_refused():
    with pytest.raises(ConfigError, match="action.gripper"):
        load_env_config({"action": {"gripper": "half"}})
