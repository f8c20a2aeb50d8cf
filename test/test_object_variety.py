"""Objects of several kinds and sizes drawn per episode (object.variety), and the observation's
object block (observation.object_features): issue #53's objects."""
import math

import numpy as np
import pytest

from fr5_rl.config import ConfigError, load_robot_spec
from fr5_rl.env_config import load_env_config
from fr5_rl.envs import FR5Env
from fr5_rl.objects import ObjectShape, yaw_of
from fr5_rl.observation import OBJECT_FEATURE_SIZE, observation_size

VARIETY = {"object": {"variety": {"enabled": True}}}


@pytest.fixture(scope="module")
def varied():
    env = FR5Env("grasp", config={**VARIETY, "observation": {"object_features": True}})
    yield env
    env.close()


def test_the_draws_cover_every_kind_within_the_configured_ranges(varied):
    variety = varied.cfg.object.variety
    kinds, squares, rectangles = set(), 0, 0
    for seed in range(80):
        varied.reset(seed=seed)
        draws = varied.episode.draws
        shape = varied.episode.plant.object_shape
        kinds.add(draws.object_shape)
        assert variety.mass[0] <= draws.object_mass <= variety.mass[1]
        if draws.object_shape == "cylinder":
            radius, height = draws.object_dims
            assert variety.cylinder_radius[0] <= radius <= variety.cylinder_radius[1]
            assert variety.cylinder_height[0] <= height <= variety.cylinder_height[1]
        else:
            half_x, half_y, half_z = draws.object_dims
            assert half_x >= half_y  # the longer top side along the box's own x
            for side in (2 * half_x, 2 * half_y):
                assert variety.box_side[0] <= side <= variety.box_side[1]
            assert variety.box_height[0] <= 2 * half_z <= variety.box_height[1]
            squares += shape.symmetry_order == 4
            rectangles += shape.symmetry_order == 2
        assert shape.grasp_width < load_robot_spec().max_opening_width
    assert kinds == {"cylinder", "box"}
    assert squares >= 5 and rectangles >= 5


def test_every_drawn_object_stands_on_the_table_at_its_rest_height(varied):
    for seed in range(12):
        varied.reset(seed=seed)
        for _ in range(5):
            varied.step(np.zeros(7, dtype=np.float32))
        pose = varied.episode.object_pose()
        assert pose.position[2] == pytest.approx(varied.object_rest_z, abs=1e-3), varied.episode.draws.object_dims
        scene = varied.episode.scene()
        assert scene.object_size == pytest.approx(varied.episode.plant.object_shape.size)
        assert scene.object_rest_z == pytest.approx(varied.cfg.table.top_height + scene.object_size[2] / 2.0)


def test_the_observation_carries_the_objects_shape(varied):
    assert varied.observation_space.shape[0] == observation_size("grasp", varied.cfg.observation)
    assert observation_size("grasp", varied.cfg.observation) == observation_size(
        "grasp", load_env_config().observation) + OBJECT_FEATURE_SIZE
    for seed in range(30):
        observation, _ = varied.reset(seed=seed)
        block = observation[-OBJECT_FEATURE_SIZE:]
        shape = varied.episode.plant.object_shape
        np.testing.assert_allclose(block[2:], np.array(shape.size) / varied.cfg.observation.object_size_scale,
                                   atol=1e-6)
        if shape.kind == "cylinder":
            assert block[0] == block[1] == 0.0
        else:
            assert block[0] ** 2 + block[1] ** 2 == pytest.approx(1.0, abs=1e-5)
            state = varied.task_state()
            tcp_quaternion = varied.episode.plant.measure().tcp_quaternion
            relative = shape.symmetry_order * (yaw_of(state.object_quaternion) - yaw_of(tcp_quaternion))
            assert block[0] == pytest.approx(math.sin(relative), abs=1e-5)
            assert block[1] == pytest.approx(math.cos(relative), abs=1e-5)


def test_a_box_turned_by_its_symmetry_reads_the_same():
    square = ObjectShape("box", (0.05, 0.05, 0.04))
    from fr5_rl.observation import object_features

    tcp_yaw = 0.0
    first, second = (object_features(square, yaw, tcp_yaw) for yaw in (0.3, 0.3 + math.pi / 2))
    assert first == pytest.approx(second, abs=1e-12)


def test_without_variety_the_configured_object_is_placed_as_before():
    plain = FR5Env("grasp")
    try:
        plain.reset(seed=3)
        assert plain.episode.draws.object_shape == plain.cfg.object.shape
        assert plain.episode.draws.object_dims == (plain.cfg.object.radius, plain.cfg.object.height)
        assert plain.observation_space.shape[0] == observation_size("grasp", plain.cfg.observation)
    finally:
        plain.close()


def test_objects_wider_than_the_stroke_or_unknown_kinds_are_refused():
    with pytest.raises(ConfigError, match="gripper opens"):
        load_env_config({"object": {"variety": {"enabled": True, "box_side": [0.03, 0.09]}}})
    with pytest.raises(ConfigError, match="kinds"):
        load_env_config({"object": {"variety": {"enabled": True, "kinds": ["sphere"]}}})
    with pytest.raises(ConfigError, match="cylinder_radius"):
        load_env_config({"object": {"variety": {"cylinder_radius": [0.03, 0.02]}}})


@pytest.mark.parametrize("seed", [11, 12, 13])
def test_the_deployed_step_sees_the_object_and_goal_as_the_place_environment_does(seed):
    """Shape, size, yaw (relative to the gripper, by symmetry) and the goal, period by period, as
    the environment builds them: one code path for both."""
    from test_deployment import run_beside_the_environment

    overrides = {"object": {"variety": {"enabled": True}}, "observation": {"object_features": True}}
    actions = np.random.default_rng(seed).uniform(-1.0, 1.0, (6, 7))
    size = observation_size("place", load_env_config(overrides).observation)
    run_beside_the_environment("place", overrides, actions, size, seed=seed)  # asserts equality each period


def test_a_box_published_with_its_longer_side_along_y_is_the_same_box_turned():
    from fr5_rl.objects import shape_from_extents

    shape, turn = shape_from_extents("box", (0.03, 0.06, 0.05))
    assert shape.size == (0.06, 0.03, 0.05) and turn == pytest.approx(math.pi / 2)
    assert shape_from_extents("box", (0.06, 0.03, 0.05)) == (shape, 0.0)
    with pytest.raises(ValueError):
        shape_from_extents("box", (0.06, -0.03, 0.05))
