"""URDF trees for launch files: the FR5 renamed for a ghost, or the part below one link.

``robot_description.py --prefix PREFIX URDF`` prints the URDF with every link renamed
``<PREFIX><name>`` (the dry run's ghost robot). ``robot_description.py --subtree ROOT URDF`` prints
only ``ROOT`` and what hangs below it: with the vendor's robot_state_publisher publishing the arm's
links on a real cell, ours publishes the gripper and the ``tcp`` below ``wrist3_Link`` and
nothing twice. A launch file's ``<param command=...>`` sets a ``robot_description`` with either,
before any node starts.
"""
from __future__ import annotations

import sys
import xml.etree.ElementTree as ET
from typing import List, Optional, Tuple

USAGE = "usage: robot_description.py --prefix PREFIX URDF | --subtree ROOT URDF"  # stdout on --help, stderr on a mistake


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


def subtree_description(urdf: str, root: str) -> Tuple[str, List[str]]:
    """``urdf`` cut to ``root`` and every link below it, and the movable joints it keeps.

    The kept root has no inertia (KDL refuses a root that has one), so robot_state_publisher
    takes it without a warning.

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
    return ET.tostring(robot, encoding="unicode"), joints


def main(argv: Optional[List[str]] = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if args and args[0] in ("-h", "--help"):
        print(USAGE + "\n\n" + __doc__.split("\n\n")[1].strip())
        return 0
    if len(args) != 3 or args[0] not in ("--prefix", "--subtree"):
        print(USAGE, file=sys.stderr)
        return 2
    try:
        with open(args[2], encoding="utf-8") as file:
            urdf = file.read()
        if args[0] == "--prefix":
            print(prefixed_description(urdf, args[1])[0])
        else:
            print(subtree_description(urdf, args[1])[0])
    except (OSError, ValueError, ET.ParseError) as error:
        print(f"robot_description.py: {error}", file=sys.stderr)
        return 2
    return 0
