"""The dry run's ghost robot: the package URDF with every link renamed, hung from the real base."""
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from fr5_rl.ros.robot_description import prefixed_description

URDF = (Path(__file__).resolve().parent.parent / "urdf" / "fr5.urdf").read_text(encoding="utf-8")


def test_every_link_is_prefixed_and_the_joints_keep_their_names():
    text, root = prefixed_description(URDF, "ghost/")
    ghost, original = ET.fromstring(text), ET.fromstring(URDF)
    assert root == "ghost/world"
    assert [link.get("name") for link in ghost.findall("link")] == \
        ["ghost/" + link.get("name") for link in original.findall("link")]
    # The ghost's joint states are the arm's commands, by the arm's joint names.
    assert [joint.get("name") for joint in ghost.findall("joint")] == [joint.get("name") for joint in original.findall("joint")]
    assert all(joint.find(end).get("link").startswith("ghost/") for joint in ghost.findall("joint") for end in ("parent", "child"))


@pytest.mark.parametrize("urdf, words", [("<model/>", "not a URDF"),
                                         ('<robot name="two"><link name="a"/><link name="b"/></robot>', "2 root links")])
def test_a_description_that_is_no_single_tree_is_refused(urdf, words):
    with pytest.raises(ValueError, match=words):
        prefixed_description(urdf, "ghost/")


# ----------------------------------------------------------------------------- the part below a link
def test_the_subtree_below_wrist3_is_the_gripper_and_the_tcp():
    """real_policy.launch arm_tf:=driver: the vendor's robot_state_publisher has the arm, ours
    publishes only what hangs below wrist3_Link, so no frame has two sources."""
    from fr5_rl.ros.robot_description import subtree_description

    text, movable = subtree_description(URDF, "wrist3_Link")
    part, whole = ET.fromstring(text), ET.fromstring(URDF)
    links = {link.get("name") for link in part.findall("link")}
    assert {"wrist3_Link", "tcp", "finger_left_link", "finger_right_link"} <= links
    arm = {"world", "base_link", "shoulder_Link", "upperarm_Link", "forearm_Link", "wrist1_Link", "wrist2_Link"}
    assert not links & arm
    assert links < {link.get("name") for link in whole.findall("link")}
    # Every joint joins two kept links (j6, which carries wrist3_Link, is the vendor's).
    assert all(joint.find(end).get("link") in links for joint in part.findall("joint") for end in ("parent", "child"))
    assert sorted(movable) == ["finger_left_joint", "finger_right_joint"]
    root = next(link for link in part.findall("link") if link.get("name") == "wrist3_Link")
    assert root.find("inertial") is None  # KDL warns about a root with inertia


def test_a_subtree_of_an_unknown_link_is_refused_with_the_links_there_are():
    from fr5_rl.ros.robot_description import main, subtree_description

    with pytest.raises(ValueError, match="no link 'wrist4_Link'.*wrist3_Link"):
        subtree_description(URDF, "wrist4_Link")
    assert main(["--subtree", "wrist4_Link", str(Path(__file__).resolve().parent.parent / "urdf" / "fr5.urdf")]) == 2
    assert main(["--nonsense"]) == 2
    assert main(["--help"]) == 0
