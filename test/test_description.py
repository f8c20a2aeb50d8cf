"""Tests of the robot descriptions urdf/<robot>.urdf (and their generator).

The reference numbers below are written out literally from the manufacturer's published numbers
(FAIRINO_FAMILY.md: the DH tables, the datasheet's limits, speeds and weights, the manual's link
masses, the DH sheets' zero-pose flange) so that the tests are independent of config/robots/ and
of the generator: if either drifts from the real arms, these tests fail. The forward kinematics
they compare against is the standard DH chain itself, not the URDF's joint origins.

PyBullet does not resolve ``package://`` URIs. To load a URDF in PyBullet, write a copy of its
text in which ``package://fr5_rl/`` is replaced by the package path + "/" (see ``pybullet_urdf``
below) and load it with ``flags=p.URDF_USE_INERTIA_FROM_FILE`` (else PyBullet recomputes the
inertias from the collision shapes' bounding boxes).
"""
from __future__ import annotations

import math
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Dict, List, Tuple

import numpy as np
import pybullet as p
import pytest

REPO = Path(__file__).resolve().parent.parent
GENERATOR = REPO / "tools" / "generate_description.py"
ARM_LINKS = ["base_link", "shoulder_Link", "upperarm_Link", "forearm_Link", "wrist1_Link", "wrist2_Link",
             "wrist3_Link"]
ARM_JOINTS = ["j1", "j2", "j3", "j4", "j5", "j6"]

# ----------------------------------------------------------------- the family (published numbers)
# d1, a2, a3, d4, d5, d6 (m): the DH tables 2.4-1 ... 2.4-6
FAMILY_DH: Dict[str, Tuple[float, ...]] = {
    "fr3": (0.140, -0.280, -0.240, 0.102, 0.102, 0.100),
    "fr5": (0.152, -0.425, -0.395, 0.102, 0.102, 0.100),
    "fr10": (0.180, -0.700, -0.586, 0.159, 0.114, 0.106),
    "fr16": (0.180, -0.520, -0.400, 0.159, 0.114, 0.106),
    "fr20": (0.215, -1.000, -0.716, 0.166, 0.138, 0.120),
    "fr30": (0.215, -0.700, -0.536, 0.166, 0.138, 0.120),
}
DH_ALPHA = (math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0)
# The flange face at q = 0 (m, base): the DH sheets (FR10's computed from its table there).
ZERO_POSE_FLANGE = {"fr3": (-0.520, -0.202, 0.038), "fr5": (-0.820, -0.202, 0.050),
                    "fr10": (-1.286, -0.265, 0.066), "fr16": (-0.920, -0.265, 0.066),
                    "fr20": (-1.716, -0.286, 0.077), "fr30": (-1.236, -0.286, 0.077)}
# link1..link6 (kg): the manual's tables; with the base they add up to the datasheet weight.
LINK_MASSES = {"fr3": (2.24, 4.94, 2.29, 1.56, 1.56, 0.36), "fr5": (4.64, 10.08, 2.71, 1.56, 1.56, 0.36),
               "fr10": (11.97, 19.59, 3.70, 1.69, 1.69, 0.35), "fr16": (11.97, 18.18, 3.22, 1.69, 1.69, 0.35),
               "fr20": (20.79, 42.84, 9.88, 4.64, 4.64, 0.60), "fr30": (20.64, 36.37, 8.41, 4.64, 4.64, 0.60)}
WEIGHT = {"fr3": 15.0, "fr5": 22.0, "fr10": 40.0, "fr16": 40.0, "fr20": 85.0, "fr30": 85.0}  # kg, datasheet
# Soft limits (rad): j3 +-160 deg (FR3 +-150 deg), the rest as in every v6 URDF.
J3_LIMIT = {"fr3": math.radians(150)}
SLOW_JOINTS = {"fr10": 2, "fr16": 2, "fr20": 3, "fr30": 3}  # j1..jN at 120 deg/s, the rest 180 deg/s
FAMILY = list(FAMILY_DH)

# The legacy FR5 file (frcobot_ros fr5_robot.urdf, 2023), which this package modelled until 2026-11
# and no arm matches: joint, parent, child, xyz, rpy. Only to measure how far it was from the arm.
LEGACY_JOINTS: List[Tuple[str, str, str, Tuple[float, ...], Tuple[float, ...]]] = [
    ("j1", "base_link", "shoulder_Link", (0, 0, 0), (0, 0, 0)),
    ("j2", "shoulder_Link", "upperarm_Link", (0, 0, 0.155), (1.570796, -1.570796, 0)),
    ("j3", "upperarm_Link", "forearm_Link", (0, 0.425, 0), (0, 0, -1.570796)),
    ("j4", "forearm_Link", "wrist1_Link", (-0.395, 0, 0), (0, 0, 1.570796)),
    ("j5", "wrist1_Link", "wrist2_Link", (0, 0, 0.13), (1.570796, 0, -1.570796)),
    ("j6", "wrist2_Link", "wrist3_Link", (0, 0, 0.102), (-1.570796, 2.268928, 0)),
]

# PGI-140-80: 0-40 mm per finger; the tcp 0.17 m beyond the flange face (the legacy file: beyond
# wrist3_Link, the wrist centre).
FINGER_JOINTS = ("finger_left_joint", "finger_right_joint")
FINGER_TRAVEL = 0.04
TCP_OFFSET = 0.17
HOME = (0.0, -1.570796, 1.570796, -1.570796, -1.570796, 0.0)
ROBOTS = FAMILY


def limits(robot: str) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lower, upper (rad) and speed (rad/s) limits of ``robot`` from the published numbers."""
    j3 = J3_LIMIT.get(robot, math.radians(160))
    slow = SLOW_JOINTS.get(robot, 0)
    speeds = np.array([math.radians(120) if i < slow else math.radians(180) for i in range(6)])
    return (np.array([-3.0543, -4.6251, -j3, -4.6251, -3.0543, -3.0543]),
            np.array([3.0543, 1.4835, j3, 1.4835, 3.0543, 3.0543]), speeds)


def urdf_file(robot: str) -> Path:
    return REPO / "urdf" / f"{robot}.urdf"


# ----------------------------------------------------------------- helpers
def rpy_matrix(r: float, pi: float, y: float) -> np.ndarray:
    """URDF fixed-axis roll-pitch-yaw: R = Rz(y) Ry(p) Rx(r)."""
    cr, sr, cp, sp, cy, sy = (math.cos(r), math.sin(r), math.cos(pi), math.sin(pi),
                              math.cos(y), math.sin(y))
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx


def reference_fk(robot: str, q: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """(flange, tcp) 4x4 poses in base_link from the published chain: the standard DH table for
    the family (frame 6 is the flange face), the legacy file's joint origins for fr5_legacy (its
    wrist3_Link, the wrist centre, was taken as the flange)."""
    t = np.eye(4)
    if robot == "fr5_legacy":
        for (_, _, _, xyz, rpy), qi in zip(LEGACY_JOINTS, q):
            origin = np.eye(4)
            origin[:3, :3] = rpy_matrix(*rpy)
            origin[:3, 3] = xyz
            turn = np.eye(4)
            turn[:3, :3] = rpy_matrix(0.0, 0.0, qi)
            t = t @ origin @ turn
    else:
        d1, a2, a3, d4, d5, d6 = FAMILY_DH[robot]
        for theta, d, a, alpha in zip(q, (d1, 0, 0, d4, d5, d6), (0, a2, a3, 0, 0, 0), DH_ALPHA):
            ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
            t = t @ np.array([[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st],
                              [0, sa, ca, d], [0, 0, 0, 1]])
    tcp = t.copy()
    tcp[:3, 3] = t[:3, 3] + TCP_OFFSET * t[:3, 2]
    return t, tcp


def rotation_angle(a: np.ndarray, b: np.ndarray) -> float:
    """Angle (rad) of the rotation between the 3x3 rotations a and b."""
    c = (np.trace(a.T @ b) - 1.0) / 2.0
    return math.acos(max(-1.0, min(1.0, c)))


class Robot:
    """A PyBullet (DIRECT) instance of a description with name -> index maps."""

    def __init__(self, urdf_path: Path, fixed: bool = True) -> None:
        self.cid = p.connect(p.DIRECT)
        self.body = p.loadURDF(str(urdf_path), useFixedBase=fixed,
                               flags=p.URDF_USE_INERTIA_FROM_FILE, physicsClientId=self.cid)
        self.joint: Dict[str, int] = {}
        self.link: Dict[str, int] = {"base_link": -1}
        self.parent: Dict[int, int] = {}
        for i in range(p.getNumJoints(self.body, physicsClientId=self.cid)):
            info = p.getJointInfo(self.body, i, physicsClientId=self.cid)
            self.joint[info[1].decode()] = i
            self.link[info[12].decode()] = i
            self.parent[i] = info[16]

    def set(self, values: Dict[str, float]) -> None:
        """Reset joints (by name) to the given positions."""
        for name, v in values.items():
            p.resetJointState(self.body, self.joint[name], v, physicsClientId=self.cid)

    def pose(self, link: str) -> np.ndarray:
        """4x4 pose of the URDF frame of ``link`` in base_link (world)."""
        st = p.getLinkState(self.body, self.link[link], computeForwardKinematics=1,
                            physicsClientId=self.cid)
        t = np.eye(4)
        t[:3, :3] = np.array(p.getMatrixFromQuaternion(st[5])).reshape(3, 3)
        t[:3, 3] = st[4]
        return t

    def close(self) -> None:
        p.disconnect(self.cid)


@pytest.fixture(scope="module", params=ROBOTS)
def arm(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory):
    """(name, URDF root element, the simulator's copy of the URDF, a PyBullet instance)."""
    from fr5_rl.sim.robot import urdf_for_pybullet

    name = request.param
    copy = tmp_path_factory.mktemp(name) / f"{name}_pybullet.urdf"
    shutil.copyfile(urdf_for_pybullet(name), copy)
    robot = Robot(copy)
    yield name, ET.parse(urdf_file(name)).getroot(), copy, robot
    robot.close()


def floats(text: str) -> List[float]:
    return [float(v) for v in text.split()]


# ----------------------------------------------------------------- structure
@pytest.mark.integration  # an external tool: `make lint`
@pytest.mark.parametrize("name", ROBOTS)
def test_check_urdf_accepts_it(name: str) -> None:
    exe = shutil.which("check_urdf")
    assert exe, "check_urdf (liburdfdom-tools) is a test dependency and must be installed"
    res = subprocess.run([exe, str(urdf_file(name))], capture_output=True, text=True)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "Successfully Parsed" in res.stdout


def test_arm_joints_are_the_published_chain_and_limits(arm) -> None:
    name, root, _, _ = arm
    assert root.get("name") == name
    joints = {j.get("name"): j for j in root.findall("joint")}
    lower, upper, speed = limits(name)
    # The vendor's v6 layout of the DH table (frcobot_ros fr5v6.urdf: j2 at z 0.152, rpy (1.5708, 0,
    # 0); j3 at x -0.425; j4 at x -0.39501; j5 at z 0.1021, rpy (1.5708, 0, 0); j6 at z 0.102, rpy
    # (-1.5708, 0, 0); its fixed joint "tool" 0.1 further along z, rpy 0: our flange).
    d1, a2, a3, d4, d5, _ = FAMILY_DH[name]
    h = math.pi / 2
    table = [((0, 0, 0), (0, 0, 0)), ((0, 0, d1), (h, 0, 0)), ((a2, 0, 0), (0, 0, 0)),
             ((a3, 0, 0), (0, 0, 0)), ((0, 0, d4), (h, 0, 0)), ((0, 0, d5), (-h, 0, 0))]
    for i, (joint, (xyz, rpy)) in enumerate(zip(ARM_JOINTS, table)):
        j = joints[joint]
        assert j.get("type") == "revolute"
        assert j.find("parent").get("link") == ARM_LINKS[i]
        assert j.find("child").get("link") == ARM_LINKS[i + 1]
        assert np.allclose(floats(j.find("origin").get("xyz")), xyz, atol=1e-9)
        assert np.allclose(floats(j.find("origin").get("rpy")), rpy, atol=1e-6)
        assert np.allclose(floats(j.find("axis").get("xyz")), (0, 0, 1))
        lim = j.find("limit")
        assert float(lim.get("lower")) == pytest.approx(lower[i], abs=1e-4)
        assert float(lim.get("upper")) == pytest.approx(upper[i], abs=1e-4)
        assert float(lim.get("velocity")) == pytest.approx(speed[i], abs=1e-4)
        assert float(lim.get("effort")) > 0


def test_gripper_and_tcp_joints(arm) -> None:
    name, root, _, _ = arm
    joints = {j.get("name"): j for j in root.findall("joint")}
    flange = "flange"  # the flange face d6 beyond the wrist centre, as the vendor's tool joint
    fj = joints["flange_joint"]
    assert fj.get("type") == "fixed" and fj.find("parent").get("link") == "wrist3_Link"
    assert fj.find("child").get("link") == "flange"
    assert np.allclose(floats(fj.find("origin").get("xyz")), (0, 0, FAMILY_DH[name][5]), atol=1e-12)
    assert np.allclose(floats(fj.find("origin").get("rpy")), (0, 0, 0), atol=1e-12)
    mount = joints["gripper_mount"]
    assert mount.get("type") == "fixed"
    assert mount.find("parent").get("link") == flange
    assert mount.find("child").get("link") == "gripper_base_link"
    mxyz = floats(mount.find("origin").get("xyz"))
    assert mxyz[0] == 0 and mxyz[1] == 0 and 0 <= mxyz[2] < TCP_OFFSET
    tcp = joints["tcp_joint"]
    assert tcp.get("type") == "fixed"
    assert tcp.find("parent").get("link") == flange
    assert tcp.find("child").get("link") == "tcp"
    assert np.allclose(floats(tcp.find("origin").get("xyz")), (0, 0, TCP_OFFSET), atol=1e-12)
    assert np.allclose(floats(tcp.find("origin").get("rpy")), (0, 0, 0), atol=1e-12)
    for joint, child, axis in (("finger_left_joint", "finger_left_link", (0, 1, 0)),
                               ("finger_right_joint", "finger_right_link", (0, -1, 0))):
        j = joints[joint]
        assert j.get("type") == "prismatic"
        assert j.find("parent").get("link") == "gripper_base_link"
        assert j.find("child").get("link") == child
        assert np.allclose(floats(j.find("axis").get("xyz")), axis)
        lim = j.find("limit")
        assert float(lim.get("lower")) == 0.0
        assert float(lim.get("upper")) == pytest.approx(FINGER_TRAVEL, abs=1e-12)
        assert float(lim.get("velocity")) > 0 and float(lim.get("effort")) > 0


def test_geometry_is_primitives_and_meshes_exist(arm) -> None:
    name, root, _, _ = arm
    total = 0
    for link in root.findall("link"):
        for col in link.findall("collision"):
            kinds = [g.tag for g in col.find("geometry")]
            assert kinds and set(kinds) <= {"box", "cylinder", "sphere"}, (link.get("name"), kinds)
        assert len(link.findall("collision")) <= 4, link.get("name")
        for mesh in link.findall("visual/geometry/mesh"):
            uri = mesh.get("filename")
            assert uri.startswith(f"package://fr5_rl/meshes/{name}/")
            path = REPO / uri[len("package://fr5_rl/"):]
            assert path.is_file(), uri
            total += path.stat().st_size
    for link_name in ARM_LINKS + ["gripper_base_link", "finger_left_link", "finger_right_link"]:
        link = root.find(f"link[@name='{link_name}']")
        assert link.findall("collision"), link_name
        assert len(link.findall("visual")) == 2, link_name     # body + dark caps
    assert total < 2 * 1024 * 1024
    for link_name in ("finger_left_link", "finger_right_link"):
        contact = root.find(f"link[@name='{link_name}']/contact")
        assert float(contact.find("lateral_friction").get("value")) == 1.0
        assert float(contact.find("spinning_friction").get("value")) == 0.001


# ----------------------------------------------------------------- PyBullet
def test_pybullet_joints_and_masses(arm) -> None:
    name, _, copy, robot = arm
    lower, upper, speed = limits(name)
    for i, joint in enumerate(ARM_JOINTS):
        info = p.getJointInfo(robot.body, robot.joint[joint], physicsClientId=robot.cid)
        assert info[2] == p.JOINT_REVOLUTE
        assert info[12].decode() == ARM_LINKS[i + 1]
        assert (info[8], info[9]) == pytest.approx((lower[i], upper[i]), abs=1e-4)
        assert info[11] == pytest.approx(speed[i], abs=1e-4)
    for joint in FINGER_JOINTS:
        info = p.getJointInfo(robot.body, robot.joint[joint], physicsClientId=robot.cid)
        assert info[2] == p.JOINT_PRISMATIC
        assert (info[8], info[9]) == pytest.approx((0.0, FINGER_TRAVEL))
    masses = LINK_MASSES[name]
    for link, mass in zip(ARM_LINKS[1:], masses):
        assert p.getDynamicsInfo(robot.body, robot.link[link], physicsClientId=robot.cid)[0] == pytest.approx(mass)
    for link in ("finger_left_link", "finger_right_link"):
        dyn = p.getDynamicsInfo(robot.body, robot.link[link], physicsClientId=robot.cid)
        assert dyn[1] == pytest.approx(1.0) and dyn[7] == pytest.approx(0.001)  # <contact>
    free = Robot(copy, fixed=False)  # a fixed base reports mass 0
    try:
        base = p.getDynamicsInfo(free.body, -1, physicsClientId=free.cid)[0]
    finally:
        free.close()
    assert base + sum(masses) == pytest.approx(WEIGHT[name], abs=0.01)  # the arm weighs what the datasheet says


def test_the_root_is_massless_for_kdl_and_pybullet_loads_base_link_as_its_base(arm) -> None:
    """robot_state_publisher (KDL) warns at every launch about a root link with inertia: the
    root is a massless ``world`` fixed to base_link, as in the vendor's URDF. The simulator's
    copy leaves it out, so its fixed base is base_link with the arm's base mass."""
    _, root, copy, robot = arm
    children = {j.find("child").get("link") for j in root.findall("joint")}
    roots = [link for link in root.findall("link") if link.get("name") not in children]
    assert [r.get("name") for r in roots] == ["world"]
    assert roots[0].find("inertial") is None
    world_joint = [j for j in root.findall("joint") if j.find("parent").get("link") == "world"]
    assert len(world_joint) == 1 and world_joint[0].get("type") == "fixed"
    assert world_joint[0].find("child").get("link") == "base_link"
    assert {link.get("name") for link in ET.parse(copy).getroot().findall("link")} == \
        {link.get("name") for link in root.findall("link")} - {"world"}
    assert p.getBodyInfo(robot.body, physicsClientId=robot.cid)[0].decode() == "base_link"


def test_inertias_are_physical(arm) -> None:
    name, root, _, _ = arm
    seen = 0
    for link in root.findall("link"):
        inertial = link.find("inertial")
        if link.get("name") in ("tcp", "world", "flange"):
            continue
        assert inertial is not None, link.get("name")
        a = {k: float(v) for k, v in inertial.find("inertia").attrib.items()}
        m = np.array([[a["ixx"], a["ixy"], a["ixz"]], [a["ixy"], a["iyy"], a["iyz"]],
                      [a["ixz"], a["iyz"], a["izz"]]])
        w = np.linalg.eigvalsh(m)
        assert w.min() > 0, link.get("name")
        assert w[0] + w[1] >= w[2] and w[0] + w[2] >= w[1] and w[1] + w[2] >= w[0]
        # The centre of mass must lie inside the bounds of the link's collision shapes.
        com = np.array(floats(inertial.find("origin").get("xyz")))
        lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
        for col in link.findall("collision"):
            c = np.array(floats(col.find("origin").get("xyz")))
            g = col.find("geometry")[0]
            # a generous reach of the primitive from its centre, whatever its rotation
            reach = float(g.get("radius", 0)) + float(g.get("length", 0)) / 2 + \
                (float(np.linalg.norm(floats(g.get("size")))) / 2 if g.get("size") else 0)
            lo, hi = np.minimum(lo, c - reach), np.maximum(hi, c + reach)
        assert np.all(com >= lo) and np.all(com <= hi), link.get("name")
        seen += 1
    assert seen == 10


def test_forward_kinematics_matches_the_published_chain(arm) -> None:
    """The URDF (in PyBullet) and the package's own forward kinematics against the DH table, at
    1,000 random poses within the limits and at zero."""
    from fr5_rl.config import load_robot_spec
    from fr5_rl.kinematics import ForwardKinematics

    name, _, _, robot = arm
    ours = ForwardKinematics(load_robot_spec(name))
    lower, upper, _ = limits(name)
    rng = np.random.default_rng(20240601)
    configs = [np.zeros(6)] + [rng.uniform(lower, upper) for _ in range(1000)]
    worst_pos, worst_rot = 0.0, 0.0
    for q in configs:
        robot.set(dict(zip(ARM_JOINTS, q)))
        flange_ref, tcp_ref = reference_fk(name, q)
        for link, ref in (("flange", flange_ref), ("tcp", tcp_ref)):
            got = robot.pose(link)
            worst_pos = max(worst_pos, float(np.linalg.norm(got[:3, 3] - ref[:3, 3])))
            worst_rot = max(worst_rot, abs(float(np.dot(got[:3, 2], ref[:3, 2])) - 1.0))
        position, rotation = ours.flange_pose(q)
        worst_pos = max(worst_pos, float(np.linalg.norm(position - flange_ref[:3, 3])))
        worst_pos = max(worst_pos, float(np.linalg.norm(ours.tcp_pose(q)[0] - tcp_ref[:3, 3])))
        worst_rot = max(worst_rot, abs(float(np.dot(rotation[:, 2], flange_ref[:3, 2])) - 1.0))
    assert worst_pos < 1e-6, f"position error {worst_pos:.2e} m"
    assert worst_rot < 1e-9, f"approach axis error {worst_rot:.2e}"


@pytest.mark.parametrize("name", FAMILY)
def test_zero_pose_flange_is_the_published_one(name: str) -> None:
    from fr5_rl.config import load_robot_spec
    from fr5_rl.kinematics import ForwardKinematics

    assert reference_fk(name, np.zeros(6))[0][:3, 3] == pytest.approx(ZERO_POSE_FLANGE[name], abs=1e-3)
    position, _ = ForwardKinematics(load_robot_spec(name)).flange_pose(np.zeros(6))
    assert position == pytest.approx(ZERO_POSE_FLANGE[name], abs=1e-3)


def test_the_current_fr5s_tcp_is_where_the_legacy_files_is_not() -> None:
    """At the home pose the legacy model's tcp stood 103 mm above the current FR5's and 28 mm
    beside it (issue #50)."""
    legacy, current = reference_fk("fr5_legacy", np.array(HOME))[1], reference_fk("fr5", np.array(HOME))[1]
    assert current[:3, 3] == pytest.approx((-0.497, -0.102, 0.307), abs=1e-3)
    assert legacy[:3, 3] - current[:3, 3] == pytest.approx((0.0, -0.028, 0.103), abs=1e-3)


def _finger_boxes(robot: Robot, link: str) -> List[Tuple[np.ndarray, np.ndarray]]:
    """Bounds (min corner, max corner) in the tcp frame (m) of each collision box of
    ``link``, from PyBullet's own shape data (all 8 corners transformed)."""
    tcp = robot.pose("tcp")
    inv = np.linalg.inv(tcp)
    st = p.getLinkState(robot.body, robot.link[link], computeForwardKinematics=1,
                        physicsClientId=robot.cid)
    com = np.eye(4)
    com[:3, :3] = np.array(p.getMatrixFromQuaternion(st[1])).reshape(3, 3)
    com[:3, 3] = st[0]
    boxes = []
    for shape in p.getCollisionShapeData(robot.body, robot.link[link], physicsClientId=robot.cid):
        assert shape[2] == p.GEOM_BOX
        local = np.eye(4)   # collision frame relative to the link's inertial (COM) frame
        local[:3, :3] = np.array(p.getMatrixFromQuaternion(shape[6])).reshape(3, 3)
        local[:3, 3] = shape[5]
        half = np.array(shape[3]) / 2.0
        corners = np.array([[sx, sy, sz, 1.0] for sx in (-1, 1) for sy in (-1, 1)
                            for sz in (-1, 1)]) * np.append(half, 1.0)
        pts = (inv @ com @ local @ corners.T).T[:, :3]
        boxes.append((pts.min(axis=0), pts.max(axis=0)))
    return boxes


@pytest.mark.parametrize("opening", [0.0, 0.005, 0.02, 0.031, FINGER_TRAVEL])
def test_fingers_open_symmetrically(arm, opening: float) -> None:
    _, _, _, robot = arm
    robot.set(dict(zip(ARM_JOINTS, HOME)))
    robot.set({"finger_left_joint": opening, "finger_right_joint": opening})
    tcp = robot.pose("tcp")
    for link, sign in (("finger_left_link", 1.0), ("finger_right_link", -1.0)):
        rel = np.linalg.inv(tcp) @ robot.pose(link)
        assert rel[:3, 3][:2] == pytest.approx((0.0, sign * opening), abs=1e-6)
        boxes = _finger_boxes(robot, link)
        # inner face of the finger = the box face nearest the tcp axis
        inner = min(b[0][1] for b in boxes) if sign > 0 else max(b[1][1] for b in boxes)
        assert inner == pytest.approx(sign * opening, abs=1e-6)
        assert all((b[0][1] >= sign * opening - 1e-6) if sign > 0 else
                   (b[1][1] <= sign * opening + 1e-6) for b in boxes)
        # the pad spans the tcp height and ends about 1 cm past it (tcp z = approach)
        tip = max(b[1][2] for b in boxes)
        assert 0.005 <= tip <= 0.02
        assert any(b[0][2] < -0.01 and b[1][2] > 0.0 for b in boxes)


def test_no_self_collision_at_home(arm) -> None:
    _, _, _, robot = arm
    robot.set(dict(zip(ARM_JOINTS, HOME)))
    robot.set({"finger_left_joint": 0.02, "finger_right_joint": 0.02})
    links = sorted(robot.link.values())
    hits = []
    for i, a in enumerate(links):
        for b in links[i + 1:]:
            if robot.parent.get(b) == a or robot.parent.get(a) == b:
                continue      # PyBullet never collides a parent with its child
            pts = p.getClosestPoints(robot.body, robot.body, 0.001, a, b,
                                     physicsClientId=robot.cid)
            if pts:
                hits.append((a, b, min(c[8] for c in pts)))
    assert not hits, hits


# ----------------------------------------------------------------- generator
@pytest.mark.integration  # the generator's command line: `make lint`
def test_generator_reproduces_committed_files(tmp_path: Path) -> None:
    res = subprocess.run([sys.executable, str(GENERATOR), "--out-dir", str(tmp_path)],
                         capture_output=True, text=True, cwd=str(tmp_path))
    assert res.returncode == 0, res.stderr
    assert sorted(f.name for f in (tmp_path / "urdf").iterdir()) == sorted(f.name for f in (REPO / "urdf").iterdir())
    for urdf in (tmp_path / "urdf").iterdir():
        assert urdf.read_bytes() == (REPO / "urdf" / urdf.name).read_bytes(), \
            f"urdf/{urdf.name} differs from the generator output: run make meshes"
    made = sorted(str(f.relative_to(tmp_path / "meshes")) for f in (tmp_path / "meshes").rglob("*.stl"))
    committed = sorted(str(f.relative_to(REPO / "meshes")) for f in (REPO / "meshes").rglob("*.stl"))
    assert made == committed
    for name in made:
        assert (tmp_path / "meshes" / name).read_bytes() == (REPO / "meshes" / name).read_bytes(), name
    cells = sorted(f.name for f in (tmp_path / "config").glob("static_transforms_*.yaml"))
    assert cells == sorted(f.name for f in (REPO / "config").glob("static_transforms_*.yaml"))
    for name in cells:
        assert (tmp_path / "config" / name).read_bytes() == (REPO / "config" / name).read_bytes(), \
            f"config/{name} differs from the generator output: run make meshes"


# The FR3's forearm is raised 33 degrees at home: the family's hung its gripper between the cell
# camera and the objects under its wrist (test_arm_cells.py).
HOMES = {**{name: HOME for name in ROBOTS}, "fr3": (0.0, -1.570796, 1.0, -1.0, -1.570796, 0.0)}


@pytest.mark.parametrize("name", ROBOTS)
def test_every_arm_has_a_description_and_the_home_pose_is_the_configs(name: str) -> None:
    from fr5_rl.config import load_robot_spec, robot_names
    from fr5_rl.kinematics import ForwardKinematics

    assert sorted(robot_names()) == sorted(ROBOTS)
    spec = load_robot_spec(name)
    assert spec.home_joint_positions == pytest.approx(HOMES[name])
    assert spec.tcp_offset == pytest.approx(TCP_OFFSET)
    # Every home points the gripper straight down (the expert keeps that rotation's yaw).
    _, rotation = ForwardKinematics(spec).tcp_pose(spec.home_joint_positions)
    assert np.asarray(rotation)[:, 2] == pytest.approx([0.0, 0.0, -1.0], abs=1e-5)


def test_view_robot_starts_at_home() -> None:
    """launch/view_robot.launch's joint_state_publisher zeros are the home pose."""
    import yaml

    zeros = yaml.safe_load((REPO / "config" / "view_robot.yaml").read_text())["zeros"]
    for joint, q in zip(ARM_JOINTS, HOME):
        assert zeros[joint] == pytest.approx(q, abs=1e-9), joint
    for joint in FINGER_JOINTS:
        assert 0.0 <= zeros[joint] <= FINGER_TRAVEL
