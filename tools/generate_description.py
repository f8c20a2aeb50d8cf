#!/usr/bin/env python3
"""Generate the description of every FAIRINO arm with its PGI-140-80 gripper from config/.

Writes ``urdf/<robot>.urdf`` (plain URDF, robot name ``<robot>``) and the visual meshes
``meshes/<robot>/<link>_white.stl`` / ``_dark.stl`` (binary STL, metres, each in its own link
frame) for each ``config/robots/<robot>.yaml``. Everything is derived from the kinematics and
masses there and in config/gripper.yaml (read through fr5_rl.config, as every other part of the
package reads them), so the script is the single source of the description:

    python tools/generate_description.py                 # rewrite the committed files (make meshes)
    python tools/generate_description.py --robot fr10    # one arm
    python tools/generate_description.py --out-dir D     # write D/urdf/*.urdf, D/meshes/*/*

The output is deterministic (same input -> byte-identical files); test/test_description.py
regenerates into a temporary directory and compares byte for byte.

Frames (all metres / radians, URDF conventions):
  * base_link: z up; at all joints zero the arm lies stretched along base -x.
  * upperarm_Link, forearm_Link, wrist1_Link: their z axis is the (parallel) j2/j3/j4
    axis; below, "lateral s" means a coordinate along that axis.
  * wrist3_Link is the wrist centre (z = the j6 axis, the approach axis). A ``flange`` link sits
    at the flange face, d6 further along j6 (the vendor's v6 ``tool_Link``), where
    gripper_base_link starts (gripper_mount_offset beyond it); ``tcp`` lies on the same axis.
  * Finger links: origin on the inner pad face; joint value = that finger's travel (m)
    from the closed centre, so the opening width is q_left + q_right.

Collision geometry uses only URDF primitives (cylinder / box), a few per link. Inertias
are the mass properties of the union of each link's collision primitives (midpoint-rule
quadrature on a regular grid) scaled to the link mass from the arm's file.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import trimesh

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "src"))  # the one description: fr5_rl.config
from fr5_rl.config import dh_joint_origins, robot_config, robot_names  # noqa: E402

from description_parts import (JointSpec, LinkSpec, box, cyl, mass_properties, num, v_cyl, v_rbox,
                               v_tube, vec)

REPO_ROOT = Path(__file__).resolve().parent.parent
MESH_URI = "package://fr5_rl/meshes/"


# --------------------------------------------------------------------------- look
WHITE_RGBA = (0.93, 0.93, 0.92, 1.0)   # arm shells (FR5 white)
DARK_RGBA = (0.20, 0.22, 0.25, 1.0)    # joint caps, flange, gripper housing, pads

# --------------------------------------------------------------------------- sizes (m)
# Chosen to look like the FR5 while keeping non-adjacent links clear of each other at the
# home pose; the kinematic lengths themselves come from config/robots/<model>.yaml. Every other
# arm of the family draws them times its drawing_scale (ArmSizes).
BASE_R, BASE_TOP, BASE_PLATE_R, BASE_PLATE_H = 0.085, 0.070, 0.095, 0.012
SHOULDER_R = 0.070            # j1 column and the j2 boss on top of it
UPPER_S = 0.135               # lateral offset of the upper-arm tube along the j2 axis
J2_HOUSING_R, J2_S0, J2_S1 = 0.068, 0.072, 0.200
ELBOW_R, ELBOW_S0, ELBOW_S1 = 0.060, 0.076, 0.196   # upper-arm side of the elbow
UPPER_TUBE_R0, UPPER_TUBE_R1 = 0.055, 0.048          # tapered upper-arm tube
FORE_ELBOW_R, FORE_ELBOW_S0 = 0.058, -0.055          # forearm side of the elbow (to ELBOW_S0)
FORE_TUBE_R0, FORE_TUBE_R1 = 0.046, 0.040            # tapered forearm tube (lateral s = 0)
WRIST_R = 0.045               # wrist housings (j4, j5, j6)
FORE_WRIST_S0, J4_SPLIT = -0.050, 0.040              # forearm/wrist1 split along the j4 axis
CAP_T = 0.010                 # thickness of a dark joint cap
WRIST3_S0 = 0.020             # wrist3 body starts here along the j6 axis
WRIST2_J6_BACK = -0.057       # back end of the j6 housing (toward -z of the flange)
# Gripper (DH-Robotics PGI-140-80 look-alike), in gripper_base_link (origin = mount face).
COUPLING_R, COUPLING_H = 0.038, 0.015
HOUSING_HX, HOUSING_HY = 0.033, 0.062                # housing half sizes (x, y = stroke axis)
FINGER_LEN = 0.050            # finger length below the housing
PAD_PAST_TCP = 0.010          # pad lower ends reach this far past the tcp
CARRIAGE_HX, CARRIAGE_Y, CARRIAGE_H = 0.018, 0.020, 0.014
PLATE_HX, PLATE_Y = 0.014, 0.012
PAD_T, PAD_LEN = 0.003, 0.030  # rubber pad thickness (y) and length (z)
FINGER_FRICTION, FINGER_SPINNING_FRICTION = 1.0, 0.001


# =========================================================================== the robot
class ArmSizes:
    """The arm's drawn sizes (the module's constants above) times ``scale``; the base's heights stay
    the FR5's (a bigger arm's shoulder is not proportionally higher: d1 grows slower than its links)."""

    NAMES = ("BASE_R", "BASE_TOP", "BASE_PLATE_R", "BASE_PLATE_H", "SHOULDER_R", "UPPER_S", "J2_HOUSING_R",
             "J2_S0", "J2_S1", "ELBOW_R", "ELBOW_S0", "ELBOW_S1", "UPPER_TUBE_R0", "UPPER_TUBE_R1",
             "FORE_ELBOW_R", "FORE_ELBOW_S0", "FORE_TUBE_R0", "FORE_TUBE_R1", "WRIST_R", "FORE_WRIST_S0",
             "J4_SPLIT", "CAP_T", "WRIST3_S0", "WRIST2_J6_BACK")

    UNSCALED = ("BASE_TOP", "BASE_PLATE_H")

    def __init__(self, scale: float) -> None:
        self.scale = scale
        for name in self.NAMES:
            setattr(self, name, globals()[name] * (1.0 if name in self.UNSCALED else scale))

    def cap(self, radius: float) -> float:
        """A dark cap's radius (m), drawn at the FR5's size, for this arm."""
        return radius * self.scale


def build_robot(cfg: dict) -> Tuple[List[LinkSpec], List[JointSpec]]:
    """All links (geometry in their own frames) and joints of one arm + gripper.

    :param cfg: :func:`fr5_rl.config.robot_config` of the arm (its gripper under ``gripper``).
    """
    arm, grip = cfg, cfg["gripper"]
    names, masses = arm["link_names"], arm["link_masses"]
    dh = {key: float(value) for key, value in arm["dh"].items()}
    origins = dh_joint_origins(dh)
    z = ArmSizes(float(arm["drawing_scale"]))
    # The vendor's v6 layout: the upper arm runs a2 (< 0) along its x to the elbow, the forearm
    # a3 (< 0) along its x to j4, the flange face d6 beyond the wrist centre.
    d1, a2, a3, d4, d5, flange_face = dh["d1"], dh["a2"], -dh["a3"], dh["d4"], dh["d5"], dh["d6"]
    upper_axis = "x"
    links: List[LinkSpec] = []
    L = {n: LinkSpec(n, float(m)) for n, m in zip(names, masses)}
    base, shoulder, upper, fore, w1, w2, w3 = (L[n] for n in names)

    # base_link (z up): mounting plate and a short pedestal under the j1 joint.
    base.collisions = [cyl("z", 0.0, z.BASE_PLATE_H, z.BASE_PLATE_R), cyl("z", 0.0, z.BASE_TOP, z.BASE_R)]
    base.dark = [v_cyl("z", 0.0, z.BASE_PLATE_H, z.BASE_PLATE_R, fillet=0.003)]
    base.white = [v_cyl("z", z.BASE_PLATE_H - 0.002, z.BASE_TOP, z.BASE_R)]

    # shoulder_Link (z up, turns with j1): column up to the j2 axis, rounded off by a
    # boss along the j2 axis (shoulder -y = lateral +s, toward the upper arm).
    s_top = (0.0, 0.0, d1)
    shoulder.collisions = [cyl("z", z.BASE_TOP, d1, z.SHOULDER_R),
                           cyl("y", -(z.J2_S0 - 0.007), z.SHOULDER_R + z.CAP_T, z.SHOULDER_R, s_top)]
    shoulder.white = [v_cyl("z", z.BASE_TOP + 0.008, d1, z.SHOULDER_R),
                      v_cyl("y", -(z.J2_S0 - 0.007), z.SHOULDER_R, z.SHOULDER_R, s_top)]
    shoulder.dark = [v_cyl("z", z.BASE_TOP, z.BASE_TOP + 0.008, z.SHOULDER_R + 0.002, fillet=0.001),
                     v_cyl("y", z.SHOULDER_R - 0.002, z.SHOULDER_R + z.CAP_T, z.cap(0.055), s_top)]

    # upperarm_Link (z = j2 axis, lateral s; the tube runs to the elbow along the upper arm's -x).
    elbow = (a2, 0.0, 0.0)
    tube_u = (0.0, 0.0, z.UPPER_S)
    sign = 1.0 if a2 > 0 else -1.0
    tube_lo, tube_hi = sorted((sign * (z.J2_HOUSING_R - 0.01), a2 - sign * (z.ELBOW_R - 0.01)))
    upper.collisions = [cyl("z", z.J2_S0, z.J2_S1 + z.CAP_T, z.J2_HOUSING_R),
                        cyl(upper_axis, tube_lo, tube_hi, z.UPPER_TUBE_R0, tube_u),
                        cyl("z", z.ELBOW_S0, z.ELBOW_S1 + z.CAP_T, z.ELBOW_R, elbow)]
    upper.white = [v_cyl("z", z.J2_S0, z.J2_S1, z.J2_HOUSING_R),
                   v_tube(upper_axis, 0.0, a2, z.UPPER_TUBE_R0, z.UPPER_TUBE_R1, tube_u) if a2 > 0 else
                   v_tube(upper_axis, a2, 0.0, z.UPPER_TUBE_R1, z.UPPER_TUBE_R0, tube_u),
                   v_cyl("z", z.ELBOW_S0, z.ELBOW_S1, z.ELBOW_R, elbow)]
    upper.dark = [v_cyl("z", z.J2_S1 - 0.002, z.J2_S1 + z.CAP_T, z.cap(0.058)),
                  v_cyl("z", z.ELBOW_S1 - 0.002, z.ELBOW_S1 + z.CAP_T, z.cap(0.050), elbow)]

    # forearm_Link (z = j3 axis; the tube runs along -x to the j4 axis at lateral s = 0).
    wrist = (-a3, 0.0, 0.0)
    fore.collisions = [cyl("z", z.FORE_ELBOW_S0 - z.CAP_T, z.ELBOW_S0, z.FORE_ELBOW_R),
                       cyl("x", -a3 + z.WRIST_R - 0.005, -z.FORE_ELBOW_R + 0.005, z.FORE_TUBE_R0),
                       cyl("z", z.FORE_WRIST_S0 - z.CAP_T, z.J4_SPLIT, z.WRIST_R, wrist)]
    fore.white = [v_cyl("z", z.FORE_ELBOW_S0, z.ELBOW_S0, z.FORE_ELBOW_R),
                  v_tube("x", -a3, 0.0, z.FORE_TUBE_R1, z.FORE_TUBE_R0),
                  v_cyl("z", z.FORE_WRIST_S0, z.J4_SPLIT, z.WRIST_R, wrist)]
    fore.dark = [v_cyl("z", z.FORE_ELBOW_S0 - z.CAP_T, z.FORE_ELBOW_S0 + 0.002, z.cap(0.048)),
                 v_cyl("z", z.FORE_WRIST_S0 - z.CAP_T, z.FORE_WRIST_S0 + 0.002, z.cap(0.038), wrist)]

    # wrist1_Link (z = j4 axis): the j4 housing, reaching past the j5 axis (at z = d4,
    # pointing along wrist1 -x); a dark cover on the far end and on the back of j5.
    j5 = (0.0, 0.0, d4)
    w1.collisions = [cyl("z", z.J4_SPLIT, d4 + z.WRIST_R + z.CAP_T - 0.002, z.WRIST_R)]
    w1.white = [v_cyl("z", z.J4_SPLIT + 0.008, d4 + z.WRIST_R, z.WRIST_R)]
    w1.dark = [v_cyl("z", z.J4_SPLIT, z.J4_SPLIT + 0.008, z.WRIST_R + 0.001, fillet=0.001),
               v_cyl("z", d4 + z.WRIST_R - 0.002, d4 + z.WRIST_R + z.CAP_T - 0.002, z.cap(0.038)),
               v_cyl("x", z.WRIST_R - 0.012, z.WRIST_R + 0.004, z.cap(0.034), j5)]

    # wrist2_Link (z = j5 axis; j6 axis along +y through z = d5): a stub out of the
    # wrist1 housing and the j6 housing, which stops short of the flange.
    j6 = (0.0, 0.0, d5)
    w2.collisions = [cyl("z", z.WRIST_R, d5 - z.WRIST_R + 0.001, z.WRIST_R),
                     cyl("y", z.WRIST2_J6_BACK - z.CAP_T, z.WRIST3_S0, z.WRIST_R, j6)]
    w2.white = [v_cyl("z", z.WRIST_R + 0.007, d5 - z.WRIST_R + 0.001, z.WRIST_R, fillet=0.002),
                v_cyl("y", z.WRIST2_J6_BACK, z.WRIST3_S0, z.WRIST_R, j6)]
    w2.dark = [v_cyl("z", z.WRIST_R, z.WRIST_R + 0.008, z.WRIST_R + 0.001, fillet=0.001),
               v_cyl("y", z.WRIST2_J6_BACK - z.CAP_T, z.WRIST2_J6_BACK + 0.002, z.cap(0.038), j6)]

    # wrist3_Link (the wrist centre, z = j6 axis): rotating cover and the dark tool flange,
    # whose face is flange_face (d6) further along j6: a little slimmer than the other wrist
    # housings, to clear the j4 housing at the home pose, and its collision stops short of the
    # face, where the gripper (the flange frame's child, not wrist3's) begins.
    w3_r, w3_end = 0.9 * z.WRIST_R, flange_face - 0.003
    w3.collisions = [cyl("z", z.WRIST3_S0, w3_end, w3_r)]
    w3.white = [v_cyl("z", z.WRIST3_S0, flange_face - 0.008, w3_r, fillet=0.002)]
    w3.dark = [v_cyl("z", flange_face - 0.009, flange_face, z.cap(0.040), fillet=0.001)]
    links += [base, shoulder, upper, fore, w1, w2, w3]
    flange = str(arm["flange_frame"])
    links.append(LinkSpec(flange, 0.0))  # a frame at the flange face, as the vendor's v6 tool_Link
    mount_offset = float(arm["gripper_mount_offset"])
    tcp_offset = mount_offset + float(grip["tcp_offset"])

    # Gripper, in gripper_base_link: origin on the mounting face, z = approach axis.
    tcp_z = tcp_offset - mount_offset                     # tcp in the gripper frame
    pad_end = tcp_z + PAD_PAST_TCP
    finger_z = pad_end - FINGER_LEN                       # housing bottom = finger origin
    if finger_z - COUPLING_H < 0.03:
        raise ValueError("tcp_offset too short for the drawn gripper housing")
    travel = float(grip["finger_travel"])
    if travel + CARRIAGE_Y > HOUSING_HY + 1e-9:
        raise ValueError("finger travel exceeds the housing")
    gb = LinkSpec("gripper_base_link", float(grip["body_mass"]))
    hx, hy = HOUSING_HX, HOUSING_HY
    gb.collisions = [cyl("z", 0.0, COUPLING_H, COUPLING_R),
                     box((-hx, -hy, COUPLING_H), (hx, hy, finger_z))]
    gb.white = [v_cyl("z", 0.0, COUPLING_H, COUPLING_R, fillet=0.002)]
    gb.dark = [v_rbox((-hx, -hy, COUPLING_H), (hx, hy, finger_z), axis="x", radius=0.008),
               # slot in which the finger carriages run (slightly proud of the housing)
               v_rbox((-CARRIAGE_HX - 0.002, -hy + 0.004, finger_z - 0.004),
                      (CARRIAGE_HX + 0.002, hy - 0.004, finger_z + 0.001), radius=0.002)]
    links.append(gb)

    fingers = []
    for side, sign in (("left", 1.0), ("right", -1.0)):
        f = LinkSpec(f"finger_{side}_link", float(grip["finger_mass"]), contact=True)

        def yb(a: float, b: float, sign: float = sign) -> Tuple[float, float]:
            """Finger-frame y interval mirrored for the right finger."""
            return (a, b) if sign > 0 else (-b, -a)

        c0, c1 = yb(0.0, CARRIAGE_Y)
        p0, p1 = yb(0.0, PLATE_Y)
        q0, q1 = yb(PAD_T, PLATE_Y)
        r0, r1 = yb(0.0, PAD_T + 0.001)
        f.collisions = [box((-CARRIAGE_HX, c0, 0.0), (CARRIAGE_HX, c1, CARRIAGE_H)),
                        box((-PLATE_HX, p0, CARRIAGE_H), (PLATE_HX, p1, FINGER_LEN))]
        f.white = [v_rbox((-CARRIAGE_HX, c0, 0.0), (CARRIAGE_HX, c1, CARRIAGE_H),
                          axis="z", radius=0.003),
                   v_rbox((-PLATE_HX, q0, CARRIAGE_H - 0.002), (PLATE_HX, q1, FINGER_LEN),
                          axis="y", radius=0.003)]
        f.dark = [v_rbox((-PLATE_HX + 0.0005, r0, FINGER_LEN - PAD_LEN),
                         (PLATE_HX - 0.0005, r1, FINGER_LEN - 0.0005), axis="y", radius=0.003)]
        fingers.append((f, sign))
        links.append(f)
    links.append(LinkSpec(str(grip["tcp_frame"]), 0.0))

    joints: List[JointSpec] = []
    parent = names[0]
    for i, (jn, o) in enumerate(zip(arm["joint_names"], origins)):
        joints.append(JointSpec(jn, "revolute", parent, names[i + 1], o["xyz"], o["rpy"],
                                (0.0, 0.0, 1.0),
                                {"lower": arm["lower_limits"][i], "upper": arm["upper_limits"][i],
                                 "effort": arm["effort_limits"][i],
                                 "velocity": arm["velocity_limits"][i]}))
        parent = names[i + 1]
    joints.append(JointSpec("flange_joint", "fixed", names[-1], flange, (0.0, 0.0, flange_face), (0.0, 0.0, 0.0)))
    joints.append(JointSpec("gripper_mount", "fixed", flange, "gripper_base_link",
                            (0.0, 0.0, mount_offset), (0.0, 0.0, 0.0)))
    finger_limit = {"lower": 0.0, "upper": travel, "effort": float(grip["finger_effort"]),
                    "velocity": float(grip["finger_velocity"])}
    for jn, (f, sign) in zip(grip["joint_names"], fingers):
        joints.append(JointSpec(jn, "prismatic", "gripper_base_link", f.name,
                                (0.0, 0.0, finger_z), (0.0, 0.0, 0.0), (0.0, sign, 0.0),
                                dict(finger_limit)))
    joints.append(JointSpec("tcp_joint", "fixed", flange, str(grip["tcp_frame"]),
                            (0.0, 0.0, tcp_offset), (0.0, 0.0, 0.0)))
    return links, joints


# =========================================================================== writers
def link_xml(link: LinkSpec, mesh_uri: str) -> List[str]:
    """URDF text of one link: inertial, visuals (mesh per material, under ``mesh_uri``), collisions."""
    out = [f'  <link name="{link.name}">']
    if link.collisions:
        mp = mass_properties(link.collisions, link.mass)
        i = mp.inertia
        out += ["    <inertial>",
                f'      <origin xyz="{vec(mp.com)}" rpy="0 0 0"/>',
                f'      <mass value="{num(mp.mass)}"/>',
                f'      <inertia ixx="{num(i[0, 0])}" ixy="{num(i[0, 1])}" ixz="{num(i[0, 2])}"'
                f' iyy="{num(i[1, 1])}" iyz="{num(i[1, 2])}" izz="{num(i[2, 2])}"/>',
                "    </inertial>"]
    else:
        # A frame only (tcp): a negligible inertial keeps PyBullet from inventing 1 kg.
        out += ["    <inertial>",
                '      <origin xyz="0 0 0" rpy="0 0 0"/>',
                '      <mass value="1e-05"/>',
                '      <inertia ixx="1e-09" ixy="0" ixz="0" iyy="1e-09" iyz="0" izz="1e-09"/>',
                "    </inertial>"]
    for material, parts in (("white", link.white), ("dark", link.dark)):
        if parts:
            out += ["    <visual>",
                    '      <origin xyz="0 0 0" rpy="0 0 0"/>',
                    f'      <geometry><mesh filename="{mesh_uri}{link.name}_{material}.stl"/>'
                    "</geometry>",
                    f'      <material name="fr5_{material}"/>',
                    "    </visual>"]
    for prim in link.collisions:
        out += ["    <collision>", "      " + prim.urdf(), "    </collision>"]
    if link.contact:
        # PyBullet reads these; grasping needs real friction on the pads.
        out += ["    <contact>",
                f'      <lateral_friction value="{num(FINGER_FRICTION)}"/>',
                f'      <spinning_friction value="{num(FINGER_SPINNING_FRICTION)}"/>',
                "    </contact>"]
    out.append("  </link>")
    return out


def joint_xml(j: JointSpec) -> List[str]:
    """URDF text of one joint."""
    out = [f'  <joint name="{j.name}" type="{j.kind}">',
           f'    <parent link="{j.parent}"/>',
           f'    <child link="{j.child}"/>',
           f'    <origin xyz="{vec(j.xyz)}" rpy="{vec(j.rpy)}"/>']
    if j.axis is not None:
        out.append(f'    <axis xyz="{vec(j.axis)}"/>')
    if j.limit is not None:
        lim = j.limit
        out.append(f'    <limit lower="{num(lim["lower"])}" upper="{num(lim["upper"])}"'
                   f' effort="{num(lim["effort"])}" velocity="{num(lim["velocity"])}"/>')
    out.append("  </joint>")
    return out


# A massless root above base_link, as the vendor's own URDF has: KDL (robot_state_publisher)
# refuses a root link with inertia and warns at every launch. PyBullet loads the robot without
# these lines (fr5_rl.sim.robot.urdf_for_pybullet strips them): its fixed base stays base_link.
ROOT_LINK_XML = [
    '  <link name="world"/>',
    '  <joint name="world_joint" type="fixed"><parent link="world"/><child link="base_link"/>'
    '<origin xyz="0 0 0" rpy="0 0 0"/></joint>',
]


def urdf_text(links: Sequence[LinkSpec], joints: Sequence[JointSpec], robot: str, title: str) -> str:
    """The complete URDF document of arm ``robot`` (its meshes in ``meshes/<robot>/``)."""
    out = ['<?xml version="1.0"?>',
           f"<!-- {title} with a DH-Robotics PGI-140-80 look-alike parallel gripper.",
           f"     GENERATED by tools/generate_description.py from config/robots/{robot}.yaml and",
           "     config/gripper.yaml: do not edit.",
           "     Meshes are referenced as package://fr5_rl/...; PyBullet does not resolve",
           "     package:// URIs (replace 'package://fr5_rl/' by the package path first) and",
           "     needs flags=URDF_USE_INERTIA_FROM_FILE to use the inertias written here. -->",
           f'<robot name="{robot}">',
           f'  <material name="fr5_white"><color rgba="{vec(WHITE_RGBA)}"/></material>',
           f'  <material name="fr5_dark"><color rgba="{vec(DARK_RGBA)}"/></material>',
           *ROOT_LINK_XML]
    by_child = {j.child: j for j in joints}
    for link in links:
        out += link_xml(link, f"{MESH_URI}{robot}/")
        if link.name in by_child:
            out += joint_xml(by_child[link.name])
    out.append("</robot>")
    return "\n".join(out) + "\n"


def mesh_files(links: Sequence[LinkSpec]) -> Dict[str, bytes]:
    """Binary STL bytes per mesh file name (one file per link and material)."""
    files: Dict[str, bytes] = {}
    for link in links:
        for material, parts in (("white", link.white), ("dark", link.dark)):
            if parts:
                mesh = trimesh.util.concatenate(parts)
                files[f"{link.name}_{material}.stl"] = mesh.export(file_type="stl")
    return files


def generate(out_dir: Path, robots: Sequence[str]) -> List[Path]:
    """Write ``urdf/<robot>.urdf`` and ``meshes/<robot>/*.stl`` under ``out_dir`` for each arm;
    return the paths written."""
    written = []
    for robot in robots:
        cfg = robot_config(robot)
        links, joints = build_robot(cfg)
        (out_dir / "urdf").mkdir(parents=True, exist_ok=True)
        (out_dir / "meshes" / robot).mkdir(parents=True, exist_ok=True)
        urdf_path = out_dir / "urdf" / f"{robot}.urdf"
        urdf_path.write_text(urdf_text(links, joints, robot, str(cfg["title"])), encoding="utf-8")
        written.append(urdf_path)
        for name, data in sorted(mesh_files(links).items()):
            path = out_dir / "meshes" / robot / name
            path.write_bytes(data)
            written.append(path)
    return written


CELL_TRANSFORMS_HEADER = """\
# GENERATED by tools/generate_description.py (make meshes) from config/static_transforms.yaml and
# config/robots/{robot}.yaml's cell: the shipped cell of the {title}, which every node takes for
# `static_transforms` when the arm is the {robot} (fr5_rl.transforms.transforms_of_arm). The camera
# looks at this arm's placement region as the FR5's looks at its own: the same angle, its distance
# scaled with the region's width, so the region fills the picture alike. The table frame is at this
# arm's table centre. The mount is the
# SIMULATOR's: calibrate a real one (calibrate_camera.py, docs/sim_to_real.md).
"""


def cell_transforms(robot: str) -> str:
    """``config/static_transforms_<robot>.yaml``'s text: the FR5's cell file moved to the arm's
    cell (camera and table follow the placement region and the table)."""
    import yaml

    from fr5_rl.config import DEFAULT_ROBOT, load_yaml

    shipped = load_yaml("static_transforms")
    fr5_cell, cell = robot_config(DEFAULT_ROBOT).get("cell", {}), robot_config(robot)["cell"]
    fr5_env = load_yaml("env")

    def region_centre(object_section):
        return [(low + high) / 2.0 for low, high in zip(object_section["region_low"], object_section["region_high"])]

    fr5_object = {**fr5_env["object"], **fr5_cell.get("object", {})}
    fr5_centre, centre = region_centre(fr5_object), region_centre(cell["object"])
    # The view scales with the region: the camera's offset from the region's centre grows (or
    # shrinks) with the region's width, so the region fills the picture as the FR5's does.
    scale = (cell["object"]["region_high"][1] - cell["object"]["region_low"][1]) / (
        fr5_object["region_high"][1] - fr5_object["region_low"][1])
    table_xy = cell["table"]["center_xy"]
    transforms = []
    for entry in shipped["transforms"]:
        xyz = list(entry["xyz"])
        if entry["child"] == "camera_link":
            offset = [xyz[0] - fr5_centre[0], xyz[1] - fr5_centre[1], xyz[2]]
            xyz = [round(centre[0] + scale * offset[0], 4), round(centre[1] + scale * offset[1], 4),
                   round(scale * offset[2], 4)]
        elif entry["child"] == "table":
            xyz[:2] = [round(value, 4) for value in table_xy]
        transforms.append({"parent": entry["parent"], "child": entry["child"], "xyz": xyz, "rpy": list(entry["rpy"])})
    body = yaml.safe_dump({"simulator_default": True, "transforms": transforms}, sort_keys=False,
                          default_flow_style=None)
    return CELL_TRANSFORMS_HEADER.format(robot=robot, title=robot_config(robot)["title"]) + body


def generate_cells(out_dir: Path, robots: Sequence[str]) -> List[Path]:
    """Write ``config/static_transforms_<robot>.yaml`` under ``out_dir`` for each arm but the FR5
    (whose cell is config/static_transforms.yaml itself); return the paths written."""
    from fr5_rl.config import DEFAULT_ROBOT

    written = []
    for robot in robots:
        if robot == DEFAULT_ROBOT:
            continue
        path = out_dir / "config" / f"static_transforms_{robot}.yaml"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(cell_transforms(robot), encoding="utf-8")
        written.append(path)
    return written


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Command line entry point."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out-dir", type=Path, default=REPO_ROOT,
                    help="root to write urdf/, meshes/ and config/static_transforms_<arm>.yaml under (default: the package)")
    ap.add_argument("--robot", action="append", choices=robot_names(),
                    help="an arm to generate (repeatable; default: every arm in config/robots/)")
    args = ap.parse_args(argv)
    robots = args.robot or robot_names()
    for path in generate(args.out_dir, robots) + generate_cells(args.out_dir, robots):
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
