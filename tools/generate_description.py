#!/usr/bin/env python3
"""Generate the FR5 + PGI-140-80 robot description from config/robot.yaml.

Writes ``urdf/fr5.urdf`` (plain URDF, robot name ``fr5``) and the visual meshes
``meshes/<link>_white.stl`` / ``meshes/<link>_dark.stl`` (binary STL, metres, each in its
own link frame). Everything is derived from the kinematics and masses in
config/robot.yaml, so the script is the single source of the description:

    python tools/generate_description.py               # rewrite the committed files
    python tools/generate_description.py --out-dir D   # write D/urdf/fr5.urdf, D/meshes/*

The output is deterministic (same input -> byte-identical files); test/test_description.py
regenerates into a temporary directory and compares byte for byte.

Frames (all metres / radians, URDF conventions):
  * base_link: z up; at all joints zero the arm lies stretched along base -x.
  * upperarm_Link, forearm_Link, wrist1_Link: their z axis is the (parallel) j2/j3/j4
    axis; below, "lateral s" means a coordinate along that axis.
  * wrist3_Link is the kinematic flange frame (on the j5 axis, z = approach axis). The
    physical mounting face of the drawn flange sits FLANGE_FACE m further along +z, where
    gripper_base_link starts; ``tcp`` is gripper.tcp_offset along the flange z axis.
  * Finger links: origin on the inner pad face; joint value = that finger's travel (m)
    from the closed centre, so the opening width is q_left + q_right.

Collision geometry uses only URDF primitives (cylinder / box), a few per link. Inertias
are the mass properties of the union of each link's collision primitives (midpoint-rule
quadrature on a regular grid) scaled to the link mass from robot.yaml.
"""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
import trimesh
import yaml

from description_parts import (JointSpec, LinkSpec, box, cyl, mass_properties, num, v_cyl, v_rbox,
                               v_tube, vec)

REPO_ROOT = Path(__file__).resolve().parent.parent
CONFIG_PATH = REPO_ROOT / "config" / "robot.yaml"
MESH_URI = "package://fr5_rl/meshes/"
ROBOT_NAME = "fr5"


# --------------------------------------------------------------------------- look
WHITE_RGBA = (0.93, 0.93, 0.92, 1.0)   # arm shells (FR5 white)
DARK_RGBA = (0.20, 0.22, 0.25, 1.0)    # joint caps, flange, gripper housing, pads

# --------------------------------------------------------------------------- sizes (m)
# Chosen to look like the FR5 while keeping non-adjacent links clear of each other at the
# home pose; the kinematic lengths themselves come from robot.yaml.
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
FLANGE_FACE = 0.045           # mounting face of the drawn flange beyond the wrist3 origin
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
def _check_layout(origins: List[dict]) -> Tuple[float, float, float, float, float]:
    """Return (d1, a2, a3, d4, d5) in metres from the joint origins and make sure they
    have the FR5 layout the drawn shapes assume (each offset along one known axis)."""
    expected_rpy = [(0, 0, 0), (1.5708, -1.5708, 0), (0, 0, -1.5708), (0, 0, 1.5708),
                    (1.5708, 0, -1.5708), (-1.5708, 2.2689, 0)]
    for o, rpy in zip(origins, expected_rpy):
        if not np.allclose(o["rpy"], rpy, atol=1e-3):
            raise ValueError(f"joint origin rpy {o['rpy']} is not the FR5 layout {rpy}")
    xyz = [np.array(o["xyz"], dtype=float) for o in origins]
    pattern = [None, 2, 1, 0, 2, 2]   # index of the only non-zero offset component
    for i, (v, k) in enumerate(zip(xyz, pattern)):
        others = np.delete(v, k) if k is not None else v
        if not np.allclose(others, 0.0):
            raise ValueError(f"joint {i + 1} origin {v} is not the FR5 layout")
    return xyz[1][2], xyz[2][1], -xyz[3][0], xyz[4][2], xyz[5][2]


def build_robot(cfg: dict) -> Tuple[List[LinkSpec], List[JointSpec]]:
    """All links (geometry in their own frames) and joints of the FR5 + gripper."""
    arm, grip = cfg["arm"], cfg["gripper"]
    names, masses = arm["link_names"], arm["link_masses"]
    d1, a2, a3, d4, d5 = _check_layout(arm["joint_origins"])
    links: List[LinkSpec] = []
    L = {n: LinkSpec(n, float(m)) for n, m in zip(names, masses)}
    base, shoulder, upper, fore, w1, w2, w3 = (L[n] for n in names)

    # base_link (z up): mounting plate and a short pedestal under the j1 joint.
    base.collisions = [cyl("z", 0.0, BASE_PLATE_H, BASE_PLATE_R), cyl("z", 0.0, BASE_TOP, BASE_R)]
    base.dark = [v_cyl("z", 0.0, BASE_PLATE_H, BASE_PLATE_R, fillet=0.003)]
    base.white = [v_cyl("z", BASE_PLATE_H - 0.002, BASE_TOP, BASE_R)]

    # shoulder_Link (z up, turns with j1): column up to the j2 axis, rounded off by a
    # boss along the j2 axis (shoulder -y = lateral +s, toward the upper arm).
    s_top = (0.0, 0.0, d1)
    shoulder.collisions = [cyl("z", BASE_TOP, d1, SHOULDER_R),
                           cyl("y", -(J2_S0 - 0.007), SHOULDER_R + CAP_T, SHOULDER_R, s_top)]
    shoulder.white = [v_cyl("z", BASE_TOP + 0.008, d1, SHOULDER_R),
                      v_cyl("y", -(J2_S0 - 0.007), SHOULDER_R, SHOULDER_R, s_top)]
    shoulder.dark = [v_cyl("z", BASE_TOP, BASE_TOP + 0.008, SHOULDER_R + 0.002, fillet=0.001),
                     v_cyl("y", SHOULDER_R - 0.002, SHOULDER_R + CAP_T, 0.055, s_top)]

    # upperarm_Link (z = j2 axis, lateral s; the tube runs along +y to the elbow).
    elbow = (0.0, a2, 0.0)
    tube_u = (0.0, 0.0, UPPER_S)
    upper.collisions = [cyl("z", J2_S0, J2_S1 + CAP_T, J2_HOUSING_R),
                        cyl("y", J2_HOUSING_R - 0.01, a2 - ELBOW_R + 0.01, UPPER_TUBE_R0, tube_u),
                        cyl("z", ELBOW_S0, ELBOW_S1 + CAP_T, ELBOW_R, elbow)]
    upper.white = [v_cyl("z", J2_S0, J2_S1, J2_HOUSING_R),
                   v_tube("y", 0.0, a2, UPPER_TUBE_R0, UPPER_TUBE_R1, tube_u),
                   v_cyl("z", ELBOW_S0, ELBOW_S1, ELBOW_R, elbow)]
    upper.dark = [v_cyl("z", J2_S1 - 0.002, J2_S1 + CAP_T, 0.058),
                  v_cyl("z", ELBOW_S1 - 0.002, ELBOW_S1 + CAP_T, 0.050, elbow)]

    # forearm_Link (z = j3 axis; the tube runs along -x to the j4 axis at lateral s = 0).
    wrist = (-a3, 0.0, 0.0)
    fore.collisions = [cyl("z", FORE_ELBOW_S0 - CAP_T, ELBOW_S0, FORE_ELBOW_R),
                       cyl("x", -a3 + WRIST_R - 0.005, -FORE_ELBOW_R + 0.005, FORE_TUBE_R0),
                       cyl("z", FORE_WRIST_S0 - CAP_T, J4_SPLIT, WRIST_R, wrist)]
    fore.white = [v_cyl("z", FORE_ELBOW_S0, ELBOW_S0, FORE_ELBOW_R),
                  v_tube("x", -a3, 0.0, FORE_TUBE_R1, FORE_TUBE_R0),
                  v_cyl("z", FORE_WRIST_S0, J4_SPLIT, WRIST_R, wrist)]
    fore.dark = [v_cyl("z", FORE_ELBOW_S0 - CAP_T, FORE_ELBOW_S0 + 0.002, 0.048),
                 v_cyl("z", FORE_WRIST_S0 - CAP_T, FORE_WRIST_S0 + 0.002, 0.038, wrist)]

    # wrist1_Link (z = j4 axis): the j4 housing, reaching past the j5 axis (at z = d4,
    # pointing along wrist1 -x); a dark cover on the far end and on the back of j5.
    j5 = (0.0, 0.0, d4)
    w1.collisions = [cyl("z", J4_SPLIT, d4 + WRIST_R + CAP_T - 0.002, WRIST_R)]
    w1.white = [v_cyl("z", J4_SPLIT + 0.008, d4 + WRIST_R, WRIST_R)]
    w1.dark = [v_cyl("z", J4_SPLIT, J4_SPLIT + 0.008, WRIST_R + 0.001, fillet=0.001),
               v_cyl("z", d4 + WRIST_R - 0.002, d4 + WRIST_R + CAP_T - 0.002, 0.038),
               v_cyl("x", WRIST_R - 0.012, WRIST_R + 0.004, 0.034, j5)]

    # wrist2_Link (z = j5 axis; j6 axis along +y through z = d5): a stub out of the
    # wrist1 housing and the j6 housing, which stops short of the flange.
    j6 = (0.0, 0.0, d5)
    w2.collisions = [cyl("z", WRIST_R, d5 - WRIST_R + 0.001, WRIST_R),
                     cyl("y", WRIST2_J6_BACK - CAP_T, WRIST3_S0, WRIST_R, j6)]
    w2.white = [v_cyl("z", WRIST_R + 0.007, d5 - WRIST_R + 0.001, WRIST_R, fillet=0.002),
                v_cyl("y", WRIST2_J6_BACK, WRIST3_S0, WRIST_R, j6)]
    w2.dark = [v_cyl("z", WRIST_R, WRIST_R + 0.008, WRIST_R + 0.001, fillet=0.001),
               v_cyl("y", WRIST2_J6_BACK - CAP_T, WRIST2_J6_BACK + 0.002, 0.038, j6)]

    # wrist3_Link (flange frame, z = j6 axis): rotating cover and the dark tool flange.
    w3.collisions = [cyl("z", WRIST3_S0, FLANGE_FACE, WRIST_R)]
    w3.white = [v_cyl("z", WRIST3_S0, FLANGE_FACE - 0.008, WRIST_R, fillet=0.002)]
    w3.dark = [v_cyl("z", FLANGE_FACE - 0.009, FLANGE_FACE, 0.040, fillet=0.001)]
    links += [base, shoulder, upper, fore, w1, w2, w3]

    # Gripper, in gripper_base_link: origin on the mounting face, z = approach axis.
    tcp_z = float(grip["tcp_offset"]) - FLANGE_FACE      # tcp in the gripper frame
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
    for i, (jn, o) in enumerate(zip(arm["joint_names"], arm["joint_origins"])):
        joints.append(JointSpec(jn, "revolute", parent, names[i + 1], o["xyz"], o["rpy"],
                                (0.0, 0.0, 1.0),
                                {"lower": arm["lower_limits"][i], "upper": arm["upper_limits"][i],
                                 "effort": arm["effort_limits"][i],
                                 "velocity": arm["velocity_limits"][i]}))
        parent = names[i + 1]
    flange = str(grip["flange_frame"])
    joints.append(JointSpec("gripper_mount", "fixed", flange, "gripper_base_link",
                            (0.0, 0.0, FLANGE_FACE), (0.0, 0.0, 0.0)))
    finger_limit = {"lower": 0.0, "upper": travel, "effort": float(grip["finger_effort"]),
                    "velocity": float(grip["finger_velocity"])}
    for jn, (f, sign) in zip(grip["joint_names"], fingers):
        joints.append(JointSpec(jn, "prismatic", "gripper_base_link", f.name,
                                (0.0, 0.0, finger_z), (0.0, 0.0, 0.0), (0.0, sign, 0.0),
                                dict(finger_limit)))
    joints.append(JointSpec("tcp_joint", "fixed", flange, str(grip["tcp_frame"]),
                            (0.0, 0.0, float(grip["tcp_offset"])), (0.0, 0.0, 0.0)))
    return links, joints


# =========================================================================== writers
def link_xml(link: LinkSpec) -> List[str]:
    """URDF text of one link: inertial, visuals (mesh per material), collisions."""
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
                    f'      <geometry><mesh filename="{MESH_URI}{link.name}_{material}.stl"/>'
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


def urdf_text(links: Sequence[LinkSpec], joints: Sequence[JointSpec]) -> str:
    """The complete URDF document."""
    out = ['<?xml version="1.0"?>',
           "<!-- FAIRINO FR5 with a DH-Robotics PGI-140-80 look-alike parallel gripper.",
           "     GENERATED by tools/generate_description.py from config/robot.yaml: do not edit.",
           "     Meshes are referenced as package://fr5_rl/...; PyBullet does not resolve",
           "     package:// URIs (replace 'package://fr5_rl/' by the package path first) and",
           "     needs flags=URDF_USE_INERTIA_FROM_FILE to use the inertias written here. -->",
           f'<robot name="{ROBOT_NAME}">',
           f'  <material name="fr5_white"><color rgba="{vec(WHITE_RGBA)}"/></material>',
           f'  <material name="fr5_dark"><color rgba="{vec(DARK_RGBA)}"/></material>',
           *ROOT_LINK_XML]
    by_child = {j.child: j for j in joints}
    for link in links:
        out += link_xml(link)
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


def generate(out_dir: Path, config_path: Path = CONFIG_PATH) -> List[Path]:
    """Write urdf/fr5.urdf and meshes/*.stl under ``out_dir``; return the paths written."""
    with open(config_path, "r", encoding="utf-8") as fh:
        cfg = yaml.safe_load(fh)
    links, joints = build_robot(cfg)
    (out_dir / "urdf").mkdir(parents=True, exist_ok=True)
    (out_dir / "meshes").mkdir(parents=True, exist_ok=True)
    written = []
    urdf_path = out_dir / "urdf" / "fr5.urdf"
    urdf_path.write_text(urdf_text(links, joints), encoding="utf-8")
    written.append(urdf_path)
    for name, data in sorted(mesh_files(links).items()):
        path = out_dir / "meshes" / name
        path.write_bytes(data)
        written.append(path)
    return written


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Command line entry point."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out-dir", type=Path, default=REPO_ROOT,
                    help="root to write urdf/ and meshes/ under (default: the package)")
    ap.add_argument("--config", type=Path, default=CONFIG_PATH, help="robot.yaml to read")
    args = ap.parse_args(argv)
    for path in generate(args.out_dir, args.config):
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
