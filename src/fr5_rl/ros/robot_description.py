"""URDF trees for launch files: an arm's description, the model's arm, renamed for a ghost, or
the part below its flange.

``robot_description.py [--robot R] [--model DIR] [--prefix PREFIX | --below-flange]`` prints the
URDF of the arm ``R`` (``urdf/<R>.urdf``), or of the arm the model in ``DIR`` was trained for, or
the FR5's; a ``--robot`` that contradicts the model's refuses (exit 2), so the launch stops before
any node starts. ``--prefix`` renames every link ``<PREFIX><name>`` (the dry run's ghost robot).
``--below-flange`` keeps only the flange and what hangs below it, attached to the vendor driver's
link at the flange face (``tool_Link`` in its current URDFs): with the vendor's
robot_state_publisher publishing the arm's links on a real cell, ours publishes the gripper and
the ``tcp`` and nothing twice. A launch file's ``<param command=...>`` sets a
``robot_description`` with it, before any node starts.
"""
from __future__ import annotations

import argparse
import sys
import xml.etree.ElementTree as ET
from typing import List, Optional, Tuple

from ..help_text import plain
from ..config import ConfigError, load_robot_spec, urdf_path
from ..deploy.bundle import ModelFilesError, arm_of



def _robot(urdf: str) -> ET.Element:
    robot = ET.fromstring(urdf)
    if robot.tag != "robot":
        raise ValueError("not a URDF <robot>")
    return robot


def _root_of(robot: ET.Element) -> str:
    children = {joint.find("child").get("link") for joint in robot.findall("joint")}
    roots = [link.get("name") for link in robot.findall("link") if link.get("name") not in children]
    if len(roots) != 1:
        raise ValueError(f"the URDF has {len(roots)} root links, a tree has one")
    return roots[0]


def robot_name(urdf: str) -> str:
    """The ``<robot name=...>`` of a URDF: the arm's model (``fr5``, ``fr10``, …) in this package's."""
    return str(_robot(urdf).get("name"))


def prefixed_description(urdf: str, prefix: str) -> Tuple[str, str]:
    """``urdf`` with every link name prefixed, and the name of its root link.

    :raises ValueError: not a URDF, or it has no single root link.
    """
    robot = _robot(urdf)
    root = _root_of(robot)
    for link in robot.findall("link"):
        link.set("name", prefix + link.get("name"))
    for joint in robot.findall("joint"):  # joints keep their names: the ghost's joint states are the arm's
        for end in ("parent", "child"):
            element = joint.find(end)
            element.set("link", prefix + element.get("link"))
    return ET.tostring(robot, encoding="unicode"), prefix + root


def subtree_description(urdf: str, root: str, attach_to: Optional[str] = None) -> Tuple[str, List[str]]:
    """``urdf`` cut to ``root`` and every link below it, and the movable joints it keeps.

    The kept root has no inertia (KDL refuses a root that has one), so robot_state_publisher
    takes it without a warning.

    :param attach_to: a link of another description (the vendor driver's at the same place) to
        hang ``root`` from, with a fixed joint that does not move it; None: ``root`` is the root.
    :raises ValueError: not a URDF, or no link named ``root``.
    """
    robot = _robot(urdf)
    names = {link.get("name") for link in robot.findall("link")}
    if root not in names:
        raise ValueError(f"the URDF has no link '{root}' (links: {', '.join(sorted(names))})")
    kept, joints = {root}, []
    grew = True
    while grew:  # a URDF lists joints in any order
        grew = False
        for joint in robot.findall("joint"):
            if joint.find("parent").get("link") in kept and joint.find("child").get("link") not in kept:
                kept.add(joint.find("child").get("link"))
                grew = True
    for element in list(robot):
        if element.tag == "link" and element.get("name") not in kept:
            robot.remove(element)
        elif element.tag == "joint":
            if element.find("parent").get("link") not in kept or element.find("child").get("link") not in kept:
                robot.remove(element)  # outside, or the joint that carries the root itself
            elif element.get("type") not in ("fixed",):
                joints.append(element.get("name"))
        elif element.tag in ("transmission", "gazebo"):
            robot.remove(element)
    for link in robot.findall("link"):
        if link.get("name") == root and link.find("inertial") is not None:
            link.remove(link.find("inertial"))
    if attach_to is not None and attach_to != root:
        ET.SubElement(robot, "link", name=attach_to)
        joint = ET.SubElement(robot, "joint", name=f"{attach_to}_to_{root}", type="fixed")
        ET.SubElement(joint, "parent", link=attach_to)
        ET.SubElement(joint, "child", link=root)
        ET.SubElement(joint, "origin", xyz="0 0 0", rpy="0 0 0")
    return ET.tostring(robot, encoding="unicode"), joints


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="robot_description.py", description=plain(__doc__.split("\n\n")[0]),
                                     epilog=plain(__doc__.split("\n\n", 1)[1]))
    parser.add_argument("--robot", default="", help="the arm (config/robots/); default: the model's, else fr5")
    parser.add_argument("--model", default="", metavar="DIR", help="a model directory: its meta.json names its arm")
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument("--prefix", default=None, help="rename every link <PREFIX><name> (a ghost robot)")
    mode.add_argument("--below-flange", action="store_true",
                      help="only the flange and below, hung from the vendor driver's flange link")
    return parser


def main(argv: Optional[List[str]] = None) -> int:
    try:
        args = build_parser().parse_args(sys.argv[1:] if argv is None else argv)
    except SystemExit as done:  # --help (0) or a mistake (2), as a status to return
        return int(done.code or 0)
    try:
        robot = arm_of(args.model or None, args.robot or None)
        spec = load_robot_spec(robot)
        urdf = urdf_path(robot).read_text(encoding="utf-8")
        if args.prefix is not None:
            urdf = prefixed_description(urdf, args.prefix)[0]
        elif args.below_flange:
            urdf = subtree_description(urdf, spec.flange_frame, spec.driver_flange_link)[0]
        print(urdf)
    except (OSError, ValueError, ET.ParseError, ConfigError, ModelFilesError) as error:
        print(f"robot_description.py: {error}", file=sys.stderr)
        return 2
    return 0
