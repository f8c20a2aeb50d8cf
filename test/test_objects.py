"""Objects' shapes, symmetry and yaw features (fr5_rl.objects): pure logic."""
import math

import numpy as np
import pytest

from fr5_rl.objects import ObjectShape, yaw_of


def quaternion_about_z(yaw):
    return (0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0))


@pytest.mark.parametrize("yaw", [-3.0, -1.2, 0.0, 0.4, 2.9])
def test_yaw_of_a_turn_about_z_is_that_turn(yaw):
    assert yaw_of(quaternion_about_z(yaw)) == pytest.approx(yaw)


def test_yaw_of_ignores_a_gripper_pointing_down():
    # Pointing down: a half turn about x, then a yaw: the x axis keeps the yaw.
    down = np.array([1.0, 0.0, 0.0, 0.0])  # (x, y, z, w): pi about x
    yaw = 0.7
    turn = np.array(quaternion_about_z(yaw))
    # turn * down (Hamilton product, x y z w)
    x1, y1, z1, w1 = turn
    x2, y2, z2, w2 = down
    product = (w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2, w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
               w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2, w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2)
    assert yaw_of(product) == pytest.approx(yaw)


def test_symmetry_orders():
    assert ObjectShape("cylinder", (0.05, 0.05, 0.1)).symmetry_order == 0
    assert ObjectShape("box", (0.05, 0.05, 0.04)).symmetry_order == 4
    assert ObjectShape("box", (0.06, 0.03, 0.04)).symmetry_order == 2


@pytest.mark.parametrize("size, period", [((0.05, 0.05, 0.04), math.pi / 2), ((0.07, 0.03, 0.05), math.pi)])
def test_yaws_the_top_cannot_tell_apart_read_the_same(size, period):
    box = ObjectShape("box", size)
    for relative in (-2.0, 0.3, 1.1):
        a = box.yaw_features(relative + 0.5, 0.5)
        b = box.yaw_features(relative + period + 0.5, 0.5)
        assert a == pytest.approx(b, abs=1e-12)
        # ... but half that period apart they differ: the encoding still sees the yaw.
        c = box.yaw_features(relative + period / 2 + 0.5, 0.5)
        assert np.hypot(a[0] - c[0], a[1] - c[1]) == pytest.approx(2.0)


def test_a_cylinders_yaw_reads_nothing_and_never_errs():
    cup = ObjectShape("cylinder", (0.05, 0.05, 0.1))
    assert cup.yaw_features(1.0, -0.3) == (0.0, 0.0)
    assert cup.yaw_error(2.0, -1.0) == 0.0


def test_yaw_error_is_modulo_the_symmetry():
    square = ObjectShape("box", (0.05, 0.05, 0.04))
    assert square.yaw_error(math.radians(95.0), 0.0) == pytest.approx(math.radians(5.0))
    rectangle = ObjectShape("box", (0.07, 0.03, 0.05))
    assert rectangle.yaw_error(math.radians(95.0), 0.0) == pytest.approx(math.radians(85.0))
    assert rectangle.yaw_error(math.radians(-170.0), 0.0) == pytest.approx(math.radians(10.0))


def test_dims_become_sizes_and_bad_ones_are_refused():
    assert ObjectShape.from_dims("cylinder", (0.025, 0.06)).size == (0.05, 0.05, 0.06)
    assert ObjectShape.from_dims("box", (0.0225,)).size == pytest.approx((0.045,) * 3)
    assert ObjectShape.from_dims("box", (0.03, 0.015, 0.02)).grasp_width == pytest.approx(0.03)
    with pytest.raises(ValueError, match="longer top side first"):
        ObjectShape("box", (0.03, 0.06, 0.05))
    with pytest.raises(ValueError, match="kind"):
        ObjectShape("sphere", (0.03, 0.03, 0.03))
    with pytest.raises(ValueError, match="positive"):
        ObjectShape("box", (0.03, float("nan"), 0.05))


def test_an_object_is_reported_by_its_kind_and_a_summary_counts_each_kind():
    from fr5_rl.objects import ObjectShape
    from fr5_rl.training.evaluation import summarise

    assert ObjectShape("cylinder", (0.05, 0.05, 0.1)).label == "cylinder"
    assert ObjectShape("box", (0.05, 0.049, 0.1)).label == "square box"  # within the 2 mm tolerance
    assert ObjectShape("box", (0.06, 0.04, 0.1)).label == "rectangular box"
    records = [{"success": True, "failure": "", "length": 100, "object": "cylinder"},
               {"success": False, "failure": "timeout", "length": 400, "object": "cylinder"},
               {"success": False, "failure": "collision", "length": 90, "object": "square box"},
               {"success": True, "failure": "", "length": 120}]
    assert summarise(records)["by_object"] == {
        "cylinder": {"successes": 1, "episodes": 2, "failures": {"timeout": 1}},
        "square box": {"successes": 0, "episodes": 1, "failures": {"collision": 1}},
        "unknown": {"successes": 1, "episodes": 1, "failures": {}}}
