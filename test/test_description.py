"""Tests of the robot description urdf/fr5.urdf (and its generator).

The reference numbers below are written out literally from the published FR5 facts
(joint origins, limits, masses) so that the test is independent of config/robot.yaml and
of the generator: if either drifts from the real robot, these tests fail.

PyBullet does not resolve ``package://`` URIs. To load the URDF in PyBullet, write a copy
of its text in which ``package://fr5_rl/`` is replaced by the package path + "/" (see
``pybullet_urdf`` below) and load it with ``flags=p.URDF_USE_INERTIA_FROM_FILE`` (else
PyBullet recomputes the inertias from the collision shapes' bounding boxes).
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
import yaml

REPO = Path(__file__).resolve().parent.parent
URDF = REPO / "urdf" / "fr5.urdf"
GENERATOR = REPO / "tools" / "generate_description.py"

# ----------------------------------------------------------------- FR5 reference (facts)
# joint, parent, child, origin xyz (m), origin rpy (rad)
FR5_JOINTS: List[Tuple[str, str, str, Tuple[float, ...], Tuple[float, ...]]] = [
    ("j1", "base_link", "shoulder_Link", (0, 0, 0), (0, 0, 0)),
    ("j2", "shoulder_Link", "upperarm_Link", (0, 0, 0.155), (1.570796, -1.570796, 0)),
    ("j3", "upperarm_Link", "forearm_Link", (0, 0.425, 0), (0, 0, -1.570796)),
    ("j4", "forearm_Link", "wrist1_Link", (-0.395, 0, 0), (0, 0, 1.570796)),
    ("j5", "wrist1_Link", "wrist2_Link", (0, 0, 0.13), (1.570796, 0, -1.570796)),
    ("j6", "wrist2_Link", "wrist3_Link", (0, 0, 0.102), (-1.570796, 2.268928, 0)),
]
# joint: lower (rad), upper (rad), max velocity (rad/s), max effort (N m)
FR5_LIMITS: Dict[str, Tuple[float, float, float, float]] = {
    "j1": (-3.0543, 3.0543, 3.15, 150.0),
    "j2": (-4.6251, 1.4835, 3.15, 150.0),
    "j3": (-2.8274, 2.8274, 3.15, 150.0),
    "j4": (-4.6251, 1.4835, 3.2, 28.0),
    "j5": (-3.0543, 3.0543, 3.2, 28.0),
    "j6": (-3.0543, 3.0543, 3.2, 28.0),
}
FR5_MASSES: Dict[str, float] = {  # kg
    "base_link": 1.62, "shoulder_Link": 4.38, "upperarm_Link": 14.46, "forearm_Link": 7.67,
    "wrist1_Link": 1.63, "wrist2_Link": 1.58, "wrist3_Link": 0.53,
}
# PGI-140-80: 0-40 mm per finger; project values for the tcp and the finger drive.
FINGER_JOINTS = ("finger_left_joint", "finger_right_joint")
FINGER_TRAVEL = 0.04       # m
TCP_OFFSET = 0.17          # m along the flange z axis
ARM_LINKS = list(FR5_MASSES)


# ----------------------------------------------------------------- helpers
def rpy_matrix(r: float, pi: float, y: float) -> np.ndarray:
    """URDF fixed-axis roll-pitch-yaw: R = Rz(y) Ry(p) Rx(r)."""
    cr, sr, cp, sp, cy, sy = (math.cos(r), math.sin(r), math.cos(pi), math.sin(pi),
                              math.cos(y), math.sin(y))
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx


def reference_fk(q: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Flange (wrist3_Link) pose in base_link from the FR5 joint-origin table:
    returns (4x4 flange pose, 4x4 tcp pose)."""
    t = np.eye(4)
    for (_, _, _, xyz, rpy), qi in zip(FR5_JOINTS, q):
        origin = np.eye(4)
        origin[:3, :3] = rpy_matrix(*rpy)
        origin[:3, 3] = xyz
        turn = np.eye(4)
        turn[:3, :3] = rpy_matrix(0.0, 0.0, qi)   # every joint turns about its local z
        t = t @ origin @ turn
    tcp = t.copy()
    tcp[:3, 3] = t[:3, 3] + TCP_OFFSET * t[:3, 2]
    return t, tcp


def rotation_angle(a: np.ndarray, b: np.ndarray) -> float:
    """Angle (rad) of the rotation between the 3x3 rotations a and b."""
    c = (np.trace(a.T @ b) - 1.0) / 2.0
    return math.acos(max(-1.0, min(1.0, c)))


def pybullet_urdf(directory: Path) -> Path:
    """The copy of urdf/fr5.urdf that the simulator loads (package:// URIs made absolute, the
    massless world root left out), copied into ``directory``."""
    from fr5_rl.sim.robot import urdf_for_pybullet

    path = directory / "fr5_pybullet.urdf"
    shutil.copyfile(urdf_for_pybullet(URDF), path)
    return path


class Robot:
    """A PyBullet (DIRECT) instance of the description with name -> index maps."""

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


@pytest.fixture(scope="module")
def urdf_copy(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return pybullet_urdf(tmp_path_factory.mktemp("urdf"))


@pytest.fixture(scope="module")
def robot(urdf_copy: Path):
    r = Robot(urdf_copy)
    yield r
    r.close()


@pytest.fixture(scope="module")
def xml_root() -> ET.Element:
    return ET.parse(URDF).getroot()


def floats(text: str) -> List[float]:
    return [float(v) for v in text.split()]


# ----------------------------------------------------------------- structure
def test_check_urdf_accepts_it() -> None:
    exe = shutil.which("check_urdf")
    assert exe, "check_urdf (liburdfdom-tools) is a test dependency and must be installed"
    res = subprocess.run([exe, str(URDF)], capture_output=True, text=True)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "Successfully Parsed" in res.stdout


def test_arm_joints_match_fr5(xml_root: ET.Element) -> None:
    assert xml_root.get("name") == "fr5"
    joints = {j.get("name"): j for j in xml_root.findall("joint")}
    for name, parent, child, xyz, rpy in FR5_JOINTS:
        j = joints[name]
        assert j.get("type") == "revolute"
        assert j.find("parent").get("link") == parent
        assert j.find("child").get("link") == child
        assert np.allclose(floats(j.find("origin").get("xyz")), xyz, atol=1e-9)
        assert np.allclose(floats(j.find("origin").get("rpy")), rpy, atol=1e-9)
        assert np.allclose(floats(j.find("axis").get("xyz")), (0, 0, 1))
        lim = j.find("limit")
        lower, upper, vel, eff = FR5_LIMITS[name]
        assert float(lim.get("lower")) == pytest.approx(lower, abs=1e-9)
        assert float(lim.get("upper")) == pytest.approx(upper, abs=1e-9)
        assert float(lim.get("velocity")) == pytest.approx(vel, abs=1e-9)
        assert float(lim.get("effort")) == pytest.approx(eff, abs=1e-9)


def test_gripper_and_tcp_joints(xml_root: ET.Element) -> None:
    joints = {j.get("name"): j for j in xml_root.findall("joint")}
    mount = joints["gripper_mount"]
    assert mount.get("type") == "fixed"
    assert mount.find("parent").get("link") == "wrist3_Link"
    assert mount.find("child").get("link") == "gripper_base_link"
    mxyz = floats(mount.find("origin").get("xyz"))
    assert mxyz[0] == 0 and mxyz[1] == 0 and 0 <= mxyz[2] < TCP_OFFSET
    tcp = joints["tcp_joint"]
    assert tcp.get("type") == "fixed"
    assert tcp.find("parent").get("link") == "wrist3_Link"
    assert tcp.find("child").get("link") == "tcp"
    assert np.allclose(floats(tcp.find("origin").get("xyz")), (0, 0, TCP_OFFSET), atol=1e-12)
    assert np.allclose(floats(tcp.find("origin").get("rpy")), (0, 0, 0), atol=1e-12)
    for name, child, axis in (("finger_left_joint", "finger_left_link", (0, 1, 0)),
                              ("finger_right_joint", "finger_right_link", (0, -1, 0))):
        j = joints[name]
        assert j.get("type") == "prismatic"
        assert j.find("parent").get("link") == "gripper_base_link"
        assert j.find("child").get("link") == child
        assert np.allclose(floats(j.find("axis").get("xyz")), axis)
        lim = j.find("limit")
        assert float(lim.get("lower")) == 0.0
        assert float(lim.get("upper")) == pytest.approx(FINGER_TRAVEL, abs=1e-12)
        assert float(lim.get("velocity")) > 0 and float(lim.get("effort")) > 0


def test_geometry_is_primitives_and_meshes_exist(xml_root: ET.Element) -> None:
    total = 0
    for link in xml_root.findall("link"):
        for col in link.findall("collision"):
            kinds = [g.tag for g in col.find("geometry")]
            assert kinds and set(kinds) <= {"box", "cylinder", "sphere"}, (link.get("name"), kinds)
        assert len(link.findall("collision")) <= 4, link.get("name")
        for mesh in link.findall("visual/geometry/mesh"):
            uri = mesh.get("filename")
            assert uri.startswith("package://fr5_rl/meshes/")
            path = REPO / uri[len("package://fr5_rl/"):]
            assert path.is_file(), uri
            total += path.stat().st_size
    for name in ARM_LINKS + ["gripper_base_link", "finger_left_link", "finger_right_link"]:
        link = xml_root.find(f"link[@name='{name}']")
        assert link.findall("collision"), name
        assert len(link.findall("visual")) == 2, name     # body + dark caps
    assert total < 2 * 1024 * 1024
    for name in ("finger_left_link", "finger_right_link"):
        contact = xml_root.find(f"link[@name='{name}']/contact")
        assert float(contact.find("lateral_friction").get("value")) == 1.0
        assert float(contact.find("spinning_friction").get("value")) == 0.001


# ----------------------------------------------------------------- PyBullet
def test_pybullet_joints_and_masses(robot: Robot, urdf_copy: Path) -> None:
    for name, _, child, _, _ in FR5_JOINTS:
        info = p.getJointInfo(robot.body, robot.joint[name], physicsClientId=robot.cid)
        lower, upper, vel, eff = FR5_LIMITS[name]
        assert info[2] == p.JOINT_REVOLUTE
        assert info[12].decode() == child
        assert (info[8], info[9]) == pytest.approx((lower, upper), abs=1e-9)
        assert info[10] == pytest.approx(eff) and info[11] == pytest.approx(vel)
    for name in FINGER_JOINTS:
        info = p.getJointInfo(robot.body, robot.joint[name], physicsClientId=robot.cid)
        assert info[2] == p.JOINT_PRISMATIC
        assert (info[8], info[9]) == pytest.approx((0.0, FINGER_TRAVEL))
    for link, mass in FR5_MASSES.items():
        if link == "base_link":
            continue   # a fixed base reports mass 0; checked on a free copy below
        assert p.getDynamicsInfo(robot.body, robot.link[link],
                                 physicsClientId=robot.cid)[0] == pytest.approx(mass)
    for name in ("finger_left_link", "finger_right_link"):
        dyn = p.getDynamicsInfo(robot.body, robot.link[name], physicsClientId=robot.cid)
        assert dyn[1] == pytest.approx(1.0) and dyn[7] == pytest.approx(0.001)  # <contact>
    free = Robot(urdf_copy, fixed=False)
    try:
        assert p.getDynamicsInfo(free.body, -1, physicsClientId=free.cid)[0] == \
            pytest.approx(FR5_MASSES["base_link"])
    finally:
        free.close()


def test_the_root_is_massless_for_kdl_and_pybullet_loads_base_link_as_its_base(
        xml_root: ET.Element, urdf_copy: Path) -> None:
    """robot_state_publisher (KDL) warns at every launch about a root link with inertia: the
    root is a massless ``world`` fixed to base_link, as in the vendor's URDF. The simulator's
    copy leaves it out, so its fixed base is base_link with the FR5's base mass."""
    children = {j.find("child").get("link") for j in xml_root.findall("joint")}
    roots = [link for link in xml_root.findall("link") if link.get("name") not in children]
    assert [root.get("name") for root in roots] == ["world"]
    assert roots[0].find("inertial") is None
    world_joint = [j for j in xml_root.findall("joint") if j.find("parent").get("link") == "world"]
    assert len(world_joint) == 1 and world_joint[0].get("type") == "fixed"
    assert world_joint[0].find("child").get("link") == "base_link"
    copy = ET.parse(urdf_copy).getroot()
    assert {link.get("name") for link in copy.findall("link")} == \
        {link.get("name") for link in xml_root.findall("link")} - {"world"}
    robot = Robot(urdf_copy)
    try:
        assert p.getBodyInfo(robot.body, physicsClientId=robot.cid)[0].decode() == "base_link"
    finally:
        robot.close()


def test_inertias_are_physical(xml_root: ET.Element) -> None:
    seen = 0
    for link in xml_root.findall("link"):
        inertial = link.find("inertial")
        if link.get("name") in ("tcp", "world"):
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


def test_forward_kinematics_matches_fr5_table(robot: Robot) -> None:
    rng = np.random.default_rng(20240601)
    lower = np.array([FR5_LIMITS[j][0] for j, *_ in FR5_JOINTS])
    upper = np.array([FR5_LIMITS[j][1] for j, *_ in FR5_JOINTS])
    names = [j for j, *_ in FR5_JOINTS]
    configs = [np.zeros(6)] + [rng.uniform(lower, upper) for _ in range(250)]
    worst_pos, worst_rot = 0.0, 0.0
    for q in configs:
        robot.set(dict(zip(names, q)))
        flange_ref, tcp_ref = reference_fk(q)
        for link, ref in (("wrist3_Link", flange_ref), ("tcp", tcp_ref)):
            got = robot.pose(link)
            worst_pos = max(worst_pos, float(np.linalg.norm(got[:3, 3] - ref[:3, 3])))
            worst_rot = max(worst_rot, rotation_angle(got[:3, :3], ref[:3, :3]))
    assert worst_pos < 1e-3, f"position error {worst_pos:.2e} m"
    assert worst_rot < 1e-3, f"orientation error {worst_rot:.2e} rad"


def test_zero_pose_is_stretched_along_minus_x() -> None:
    flange, _ = reference_fk(np.zeros(6))
    assert flange[:3, 3] == pytest.approx((-0.82, -0.13, 0.053), abs=1e-6)


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
def test_fingers_open_symmetrically(robot: Robot, opening: float) -> None:
    home = yaml.safe_load((REPO / "config" / "robot.yaml").read_text())["home_joint_positions"]
    robot.set(dict(zip([j for j, *_ in FR5_JOINTS], home)))
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


def test_no_self_collision_at_home(robot: Robot) -> None:
    home = yaml.safe_load((REPO / "config" / "robot.yaml").read_text())["home_joint_positions"]
    robot.set(dict(zip([j for j, *_ in FR5_JOINTS], home)))
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
def test_generator_reproduces_committed_files(tmp_path: Path) -> None:
    res = subprocess.run([sys.executable, str(GENERATOR), "--out-dir", str(tmp_path)],
                         capture_output=True, text=True, cwd=str(tmp_path))
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "urdf" / "fr5.urdf").read_bytes() == URDF.read_bytes(), \
        "urdf/fr5.urdf differs from the generator output: run tools/generate_description.py"
    made = sorted(f.name for f in (tmp_path / "meshes").iterdir())
    committed = sorted(f.name for f in (REPO / "meshes").glob("*.stl"))
    assert made == committed
    for name in made:
        assert (tmp_path / "meshes" / name).read_bytes() == (REPO / "meshes" / name).read_bytes(), name


def test_view_robot_starts_at_home() -> None:
    """launch/view_robot.launch's joint_state_publisher zeros are robot.yaml's home."""
    cfg = yaml.safe_load((REPO / "config" / "robot.yaml").read_text())
    zeros = yaml.safe_load((REPO / "config" / "view_robot.yaml").read_text())["zeros"]
    for name, q in zip(cfg["arm"]["joint_names"], cfg["home_joint_positions"]):
        assert zeros[name] == pytest.approx(q, abs=1e-9), name
    for name in FINGER_JOINTS:
        assert 0.0 <= zeros[name] <= FINGER_TRAVEL
