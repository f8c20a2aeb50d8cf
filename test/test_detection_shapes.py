"""The detector tells a box's top from a cylinder's and measures a box's yaw and sides (issue #53),
on synthetic depth images seen from straight above (test_detection's camera and table)."""
import math

import numpy as np
import pytest

from fr5_rl.objects import ObjectShape
from fr5_rl.perception.detector import Detection
from test_detection import K, detect


def shapes_scene(kind, cx, cy, length, width, height, yaw=0.0):
    """Depth (m) of the table with one box (sides ``length`` x ``width`` turned by ``yaw``) or one
    cylinder (diameter ``length``), seen from 1 m above."""
    u, v = np.meshgrid(np.arange(K.width), np.arange(K.height))
    x, y = K.ray(u, v)
    depth = np.ones((K.height, K.width), dtype=np.float32)
    z = 1.0 - height
    tx, ty = x * z - cx, -(y * z) - cy
    if kind == "cylinder":
        inside = tx ** 2 + ty ** 2 <= (length / 2.0) ** 2
    else:
        along = tx * math.cos(yaw) + ty * math.sin(yaw)
        across = -tx * math.sin(yaw) + ty * math.cos(yaw)
        inside = (np.abs(along) <= length / 2.0) & (np.abs(across) <= width / 2.0)
    depth[inside] = z
    return depth


@pytest.mark.parametrize("length, width, yaw", [(0.06, 0.03, 0.0), (0.07, 0.035, 0.7), (0.05, 0.04, -1.2),
                                                (0.045, 0.045, 0.3), (0.06, 0.03, 2.5)])
def test_a_boxs_yaw_and_sides_are_measured_by_its_symmetry(length, width, yaw):
    found = detect(shapes_scene("box", 0.05, -0.04, length, width, 0.05, yaw))
    assert isinstance(found, Detection), found
    assert found.kind == "box"
    assert found.extents == pytest.approx((length, width), abs=0.003)
    shape = ObjectShape("box", (length, width, 0.05))
    # By the top's symmetry: a square's yaw modulo 90 deg (from its fourth moments).
    assert shape.yaw_error(found.yaw, yaw) < math.radians(2.0)


@pytest.mark.parametrize("diameter", [0.04, 0.05, 0.07])
def test_a_cylinders_top_is_a_disc(diameter):
    found = detect(shapes_scene("cylinder", -0.05, 0.06, diameter, diameter, 0.08))
    assert isinstance(found, Detection), found
    assert found.kind == "cylinder" and found.yaw == 0.0
    assert found.extents == pytest.approx((diameter, diameter), abs=0.003)
