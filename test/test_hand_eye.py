"""Hand-eye calibration of the fixed camera (issue #29): the solver on synthetic data, its
refusals, the cup measurement on rendered images, the result file, the command line's refusals,
the simulator's hold and the simulated camera's hidden mount offset."""
import dataclasses
import math

import numpy as np
import pytest

from fr5_rl.config import ConfigError, load_robot_spec, load_yaml, typed
from fr5_rl.ros.calibration_motion import CalibrationMove, calibration_poses, centre_configuration
from fr5_rl.deploy.deployment import SafetyZone
from fr5_rl.motion_guard import MotionGuardSettings
from fr5_rl.env_config import load_env_config
from fr5_rl.perception.camera_model import Intrinsics
from fr5_rl.perception.hand_eye import (CalibrationRefused, calibrated_transforms_yaml, check_pose_set,
                                        fit_cylinder_centre, load_calibration_settings, measure_cup, offset_transform,
                                        rotation_from_vector, rpy_from_rotation, solve_hand_eye,
                                        solve_rejecting_outliers, tcp_poses_from_joints, transform_error,
                                        vector_from_rotation, write_result)
from fr5_rl.kinematics import rotation_from_rpy
from fr5_rl.ros.calibrate_camera import main as calibrate_main
from fr5_rl.ros.calibrate_camera import rest_periods
from fr5_rl.ros.camera_node import CameraNodeParams
from fr5_rl.transforms import load_static_transforms, load_transform_files, quaternion_from_matrix, transform_in

SETTINGS = load_calibration_settings()
ROBOT = load_robot_spec()
ENV = load_env_config()
GUARD = typed(MotionGuardSettings, load_yaml("policy_node")["guard"], "config/policy_node.yaml", "guard")
CAMERA = load_yaml("camera")
K = Intrinsics(CAMERA["width"], CAMERA["height"], CAMERA["fx"], CAMERA["fy"], CAMERA["cx"], CAMERA["cy"])
ENTRIES = load_transform_files(["static_transforms", "camera_frames"])
MOUNT = transform_in(ENTRIES, "base_link", "camera_link")
MOUNT_FROM_OPTICAL = transform_in(ENTRIES, "camera_link", "camera_color_optical_frame")
OFFSET = [0.02, 0.015, -0.015, -0.03, 0.03, 0.025]  # 2.9 cm, 2.8 deg
CUP_IN_TCP = np.array([0.004, -0.003, 0.025])


def _poses(count: int = 12, seed: int = 0) -> np.ndarray:
    settings = dataclasses.replace(SETTINGS, seed=seed)
    joints = calibration_poses(settings, ROBOT, ENV, GUARD, MOUNT @ MOUNT_FROM_OPTICAL, K, count, CUP_IN_TCP)
    return tcp_poses_from_joints(ROBOT, joints)


def _measured(poses: np.ndarray, true_mount: np.ndarray, noise: float, seed: int = 0) -> np.ndarray:
    """The cup centre in the true optical frame (m), with Gaussian noise (m per axis)."""
    base_from_optical = true_mount @ MOUNT_FROM_OPTICAL
    cup = np.einsum("nij,j->ni", poses[:, :3, :3], CUP_IN_TCP) + poses[:, :3, 3]
    exact = (cup - base_from_optical[:3, 3]) @ base_from_optical[:3, :3]
    return exact + np.random.default_rng(seed).normal(0.0, noise, exact.shape)


# ----------------------------------------------------------------------------- the solve
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_solver_recovers_a_known_mount_and_cup_offset_from_noisy_data(seed):
    true = MOUNT @ offset_transform(OFFSET)
    poses = _poses(12, seed)
    result = solve_hand_eye(poses, _measured(poses, true, 0.0005, seed), MOUNT, MOUNT_FROM_OPTICAL,
                            SETTINGS.max_condition)
    error_m, error_rad = transform_error(result.base_from_mount, true)
    assert error_m < 0.003 and math.degrees(error_rad) < 0.2, (error_m, math.degrees(error_rad))
    assert np.linalg.norm(result.object_in_tcp - CUP_IN_TCP) < 0.003
    assert 0.3 < result.rms_mm < 2.0 and result.max_mm >= result.rms_mm  # the noise shows in the residual
    # The configured mount, which the solve starts from, is far off: the test can fail.
    assert transform_error(MOUNT, true)[0] > 0.02


def test_solver_without_noise_is_exact():
    true = MOUNT @ offset_transform(OFFSET)
    poses = _poses(8)
    result = solve_hand_eye(poses, _measured(poses, true, 0.0), MOUNT, MOUNT_FROM_OPTICAL, SETTINGS.max_condition)
    error_m, error_rad = transform_error(result.base_from_mount, true)
    assert error_m < 1e-6 and error_rad < 1e-6 and result.max_mm < 1e-3


def test_an_outlier_pose_is_dropped_and_the_rest_fit():
    true = MOUNT @ offset_transform(OFFSET)
    poses = _poses(12)
    measured = _measured(poses, true, 0.0003)
    measured[4] += [0.006, -0.004, 0.008]  # an occlusion the checks missed
    result, dropped = solve_rejecting_outliers(poses, measured, MOUNT, MOUNT_FROM_OPTICAL, SETTINGS.max_condition,
                                               SETTINGS.min_poses, SETTINGS.max_residual)
    assert dropped == [4]
    assert transform_error(result.base_from_mount, true)[0] < 0.002


def test_too_few_poses_are_refused_saying_how_many_more():
    with pytest.raises(CalibrationRefused, match=r"4 usable pose\(s\), at least 6 needed: 2 more"):
        check_pose_set(_poses(4), 6, SETTINGS.min_position_spread, SETTINGS.min_rotation_spread)


def test_collinear_positions_are_refused():
    poses = _poses(10)
    line = np.linspace(-0.1, 0.1, len(poses))
    poses[:, :3, 3] = np.array([-0.5, 0.0, 0.15]) + np.outer(line, [0.0, 1.0, 0.0])  # orientations still vary
    with pytest.raises(CalibrationRefused, match="near-collinear.*spread the poses"):
        check_pose_set(poses, 6, SETTINGS.min_position_spread, SETTINGS.min_rotation_spread)


def test_a_fixed_orientation_is_refused():
    poses = _poses(10)
    poses[:, :3, :3] = poses[0, :3, :3]
    with pytest.raises(CalibrationRefused, match=r"orientation does not vary enough.*tilts \(j4, j5\) and the yaw"):
        check_pose_set(poses, 6, SETTINGS.min_position_spread, SETTINGS.min_rotation_spread)


def test_yaw_alone_is_refused_it_confounds_the_cup_offset_along_the_axis():
    poses = _poses(10)
    for index, pose in enumerate(poses):
        pose[:3, :3] = poses[0, :3, :3] @ rotation_from_rpy(0.0, 0.0, 0.3 * index)
    with pytest.raises(CalibrationRefused, match="does not vary enough"):
        check_pose_set(poses, 6, SETTINGS.min_position_spread, SETTINGS.min_rotation_spread)
    # Past the checks, the solve itself sees the degenerate Jacobian and prints it.
    with pytest.raises(CalibrationRefused, match=r"condition number .* smallest singular value"):
        solve_hand_eye(poses, _measured(poses, MOUNT, 0.0), MOUNT, MOUNT_FROM_OPTICAL, SETTINGS.max_condition)


def test_the_generated_poses_are_safe_reachable_and_varied():
    joints = calibration_poses(SETTINGS, ROBOT, ENV, GUARD, MOUNT @ MOUNT_FROM_OPTICAL, K, 12, CUP_IN_TCP)
    zone = SafetyZone(ROBOT, ENV)
    for q in joints:
        assert np.all(q >= ROBOT.lower_limits + GUARD.joint_limit_margin)
        assert np.all(q <= ROBOT.upper_limits - GUARD.joint_limit_margin)
        assert zone.check(q) is None
    check_pose_set(tcp_poses_from_joints(ROBOT, joints), SETTINGS.min_poses, SETTINGS.min_position_spread,
                   SETTINGS.min_rotation_spread, CUP_IN_TCP)


def test_the_move_is_slow_synchronised_and_gated():
    move = CalibrationMove(ROBOT, ENV, GUARD, 0.25, 0.002, 0.005, 0.02)
    start = centre_configuration(SETTINGS, ROBOT)
    target = start + [0.2, -0.1, 0.1, 0.2, -0.2, 0.5]
    move.start(target)
    q, now = start.copy(), 0.0
    for _ in range(2000):
        command, why = move.step(q, np.zeros(6), now)
        assert why is None
        if command is None:
            break
        assert np.max(np.abs(command - q)) <= 0.25 * 0.02 + 1e-9  # the slowest-joint speed cap
        q, now = command, now + 0.02
    assert np.max(np.abs(q - target)) <= 0.002
    # A target that takes the tcp below the table: the move stops at the safety gate, and no
    # command it sent left the safety zone.
    zone = SafetyZone(ROBOT, ENV)
    move.start(centre_configuration(SETTINGS, ROBOT) + [0.0, 0.15, 0.0, 0.0, 0.0, 0.0])
    why = None
    for _ in range(2000):
        command, why = move.step(q, np.zeros(6), now)
        if command is None:
            break
        assert zone.check(command) is None
        q, now = command, now + 0.02
    assert why is not None and why.startswith("safety gate: ")


# ----------------------------------------------------------------------------- the measurement
def test_cylinder_fit_finds_the_centre_not_the_visible_surface():
    rng = np.random.default_rng(0)
    centre, axis = np.array([0.05, -0.02, 0.9]), np.array([0.1, -0.95, 0.3])
    axis /= np.linalg.norm(axis)
    cup = SETTINGS.cup
    u = np.cross(axis, [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    angles, heights = rng.uniform(0, 2 * np.pi, 4000), rng.uniform(-cup.height / 2, cup.height / 2, 4000)
    side = centre + np.outer(np.cos(angles), u) * cup.radius + np.outer(np.sin(angles), v) * cup.radius + np.outer(heights, axis)
    radii, turns = cup.radius * np.sqrt(rng.uniform(0, 1, 1500)), rng.uniform(0, 2 * np.pi, 1500)
    cap = centre - axis * cup.height / 2 + np.outer(radii * np.cos(turns), u) + np.outer(radii * np.sin(turns), v)
    points = np.vstack([side, cap])
    points = points[(points - centre) @ (-centre / np.linalg.norm(centre)) > -0.004]  # what the camera sees
    points += rng.normal(0.0, 0.0005, points.shape)
    found, on_cap = fit_cylinder_centre(points, axis + [0.05, 0.0, 0.0], cup)
    assert np.linalg.norm(found - centre) < 0.0007
    assert on_cap > cup.min_cap_pixels
    assert np.linalg.norm(points.mean(axis=0) - centre) > 0.005  # the naive centroid would be off


def test_the_held_cup_is_measured_on_a_rendered_frame():
    from fr5_rl.sim.camera import SimulatedCamera, depth_to_millimetres

    base_from_optical = MOUNT @ MOUNT_FROM_OPTICAL
    joints = calibration_poses(SETTINGS, ROBOT, ENV, GUARD, base_from_optical, K, 3, CUP_IN_TCP)
    camera = SimulatedCamera(ENV, list(ROBOT.joint_names) + list(ROBOT.finger_joint_names), base_from_optical,
                             K.opengl_projection(CAMERA["near"], CAMERA["far"]), K.width, K.height, CAMERA["near"],
                             CAMERA["far"], renderer="tiny")
    optical_from_base = np.linalg.inv(base_from_optical)
    try:
        measured = 0
        for q, pose in zip(joints, tcp_poses_from_joints(ROBOT, joints)):
            camera.set_joints({**dict(zip(ROBOT.joint_names, q)), **{n: 0.025 for n in ROBOT.finger_joint_names}})
            centre = pose[:3, :3] @ CUP_IN_TCP + pose[:3, 3]
            camera.set_object("cylinder", (SETTINGS.cup.radius, SETTINGS.cup.height), centre,
                              quaternion_from_matrix(pose[:3, :3] @ np.diag([1.0, -1.0, -1.0])))
            rgb, depth = camera.render()
            axis = optical_from_base[:3, :3] @ (pose[:3, :3] @ np.array(SETTINGS.cup.axis_in_tcp))
            found = measure_cup(rgb, depth_to_millimetres(depth).astype(np.float32) / 1000.0, K, axis, SETTINGS.cup)
            if found is None:
                continue  # the gripper hides its top at this pose: skipped, as the tool does
            truth = optical_from_base[:3, :3] @ centre + optical_from_base[:3, 3]
            assert np.linalg.norm(found - truth) < 0.0025  # 1 mm depth steps, rasterised edges
            measured += 1
        assert measured >= 2
    finally:
        camera.close()


# ----------------------------------------------------------------------------- the result file
def test_the_result_file_round_trips_through_the_transform_loader(tmp_path):
    calibrated = MOUNT @ offset_transform(OFFSET)
    text = calibrated_transforms_yaml(load_static_transforms(), "base_link", "camera_link", calibrated, "test\nrun")
    path = tmp_path / "calibrated.yaml"
    write_result(path, text, force=False)
    entries = load_static_transforms(path)
    by_child = {entry["child"]: entry for entry in entries}
    assert set(by_child) == {entry["child"] for entry in load_static_transforms()}  # the others kept
    np.testing.assert_allclose(by_child["camera_link"]["matrix"], calibrated, atol=2e-6)
    np.testing.assert_array_equal(by_child["table"]["matrix"],
                                  {e["child"]: e for e in load_static_transforms()}["table"]["matrix"])
    assert path.read_text().startswith("# test\n# run\n")
    # Loaded together with the camera's chain, as static_transforms_node and the detector do.
    assert transform_in(load_transform_files([path, "camera_frames"]), "base_link", "camera_color_optical_frame").shape == (4, 4)


def test_an_existing_result_is_kept_unless_forced(tmp_path):
    path = tmp_path / "calibrated.yaml"
    path.write_text("keep me")
    with pytest.raises(CalibrationRefused, match="exists: pass --force"):
        write_result(path, "new", force=False)
    assert path.read_text() == "keep me"
    write_result(path, "new", force=True)
    assert path.read_text() == "new"


def test_rotations_round_trip():
    rng = np.random.default_rng(3)
    for _ in range(20):
        rotation = rotation_from_vector(rng.normal(0, 1.0, 3))
        assert np.allclose(rotation_from_rpy(*rpy_from_rotation(rotation)), rotation, atol=1e-12)
        assert np.allclose(rotation_from_vector(vector_from_rotation(rotation)), rotation, atol=1e-9)


# ----------------------------------------------------------------------------- the command line
def test_cli_refuses_an_existing_output_without_force(tmp_path, capsys):
    path = tmp_path / "out.yaml"
    path.write_text("keep me")
    assert calibrate_main(["--out", str(path)]) == 2
    assert path.read_text() == "keep me"
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "exists: pass --force" in err[0]


def test_cli_refuses_too_few_poses(tmp_path, capsys):
    assert calibrate_main(["--out", str(tmp_path / "out.yaml"), "--poses", "4"]) == 2
    assert "at least 6 needed: 2 more" in capsys.readouterr().err
    assert not (tmp_path / "out.yaml").exists()


def test_cli_refuses_a_bag_without_the_camera_topics(tmp_path, capsys):
    rosbag = pytest.importorskip("rosbag")
    import rospy
    from sensor_msgs.msg import JointState

    bag_path = tmp_path / "joints_only.bag"
    with rosbag.Bag(str(bag_path), "w") as bag:
        for k in range(10):
            message = JointState(name=list(ROBOT.joint_names), position=list(centre_configuration(SETTINGS, ROBOT)))
            message.header.stamp = rospy.Time(1.0 + 0.01 * k)
            bag.write(SETTINGS.joint_states_topic, message, message.header.stamp)
    assert calibrate_main(["--out", str(tmp_path / "out.yaml"), "--bag", str(bag_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"lacks the topic {SETTINGS.color_topic}" in err[0]
    assert not (tmp_path / "out.yaml").exists()


def test_rest_periods_are_found_in_joint_states():
    stamps = np.arange(0.0, 6.0, 0.005)
    q = np.where(stamps < 2.0, 0.0, np.where(stamps < 3.0, (stamps - 2.0) * 0.2, 0.2))
    positions = np.tile(q[:, None], (1, 6))
    periods = rest_periods(stamps, positions, 0.005, 0.6)
    assert len(periods) == 2
    assert periods[0][0] == 0.0 and 1.9 < periods[0][1] <= 2.06
    assert 2.99 <= periods[1][0] < 3.1 and periods[1][1] == pytest.approx(stamps[-1])


# ----------------------------------------------------------------------------- the simulator
def test_camera_mount_offset_is_validated_naming_the_parameter():
    for bad in ([0.0] * 5, [0.0] * 5 + [float("nan")], [0.0] * 7):
        with pytest.raises(ConfigError, match="'mount_offset' must be 6 finite numbers"):
            typed(CameraNodeParams, {**CAMERA, "mount_offset": bad}, "camera")
    with pytest.raises(ConfigError, match="mount_offset"):
        typed(CameraNodeParams, {**CAMERA, "mount_offset": [0, 0, 0, "a", 0, 0]}, "camera")


def test_camera_mount_offset_moves_the_render_pose_only():
    configured, frames = typed(CameraNodeParams, CAMERA, "camera").transforms()
    np.testing.assert_array_equal(configured, transform_in(ENTRIES, "base_link", "camera_color_optical_frame"))
    render, frames_offset = typed(CameraNodeParams, {**CAMERA, "mount_offset": OFFSET}, "camera").transforms()
    # Rendered from T_base_link(configured) . T(offset) . chain ...
    np.testing.assert_allclose(render, MOUNT @ offset_transform(OFFSET) @ MOUNT_FROM_OPTICAL, atol=1e-12)
    # ... while what goes on tf (the camera's chain; the mount is static_transforms_node's) is unchanged.
    assert [(e["parent"], e["child"], e["xyz"], e["rpy"]) for e in frames_offset] == \
        [(e["parent"], e["child"], e["xyz"], e["rpy"]) for e in frames]
    error_m, error_rad = transform_error(render, configured)
    assert error_m > 0.02 and math.degrees(error_rad) > 2.5


def test_simulator_holds_the_cup_fixed_in_the_tcp_while_the_arm_moves():
    from fr5_rl.envs import FR5Env
    from fr5_rl.sim.held_object import HeldObject

    env = FR5Env(task="reach", config={"reach": {"simulation": {"physics_dt": 0.005}}})
    try:
        env.reset(seed=1_100_000)
        held = HeldObject(env.plant.world.client, env.plant.robot.body, env.plant.robot.tcp_link, env.plant.world.object_id,
                          [env.plant.world.table_id])
        held.hold(CUP_IN_TCP)
        start = env.joint_positions()
        for step in range(600):  # 3 s: a slow move, then rest
            share = min(1.0, step / 400)
            env.episode.advance_physics(start + share * np.array([0.2, -0.1, 0.1, 0.2, -0.2, 0.4]), 0.05)
        pose = tcp_poses_from_joints(ROBOT, [env.joint_positions()])[0]
        expected = pose[:3, :3] @ CUP_IN_TCP + pose[:3, 3]
        assert np.linalg.norm(env.object_position() - expected) < 0.001
        held.release()
    finally:
        env.close()
