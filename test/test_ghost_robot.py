"""The dry run's ghost robot: the package URDF with every link renamed, hung from the real base."""
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from fr5_rl.ros.robot_description import prefixed_description

REPO = Path(__file__).resolve().parent.parent
URDF = (REPO / "urdf" / "fr5.urdf").read_text(encoding="utf-8")


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


# ----------------------------------------------------------------------------- the part below the flange
def test_below_the_flange_is_the_gripper_and_the_tcp_hung_from_the_vendors_tool_link():
    """real_policy.launch arm_tf:=driver: the vendor's robot_state_publisher has the arm (its current
    URDFs end in tool_Link at the flange face), ours publishes only the flange and what hangs below
    it, so no frame has two sources."""
    from fr5_rl.ros.robot_description import subtree_description

    text, movable = subtree_description(URDF, "flange", "tool_Link")
    part, whole = ET.fromstring(text), ET.fromstring(URDF)
    links = {link.get("name") for link in part.findall("link")}
    assert {"tool_Link", "flange", "tcp", "finger_left_link", "finger_right_link"} <= links
    arm = {"world", "base_link", "shoulder_Link", "upperarm_Link", "forearm_Link", "wrist1_Link", "wrist2_Link",
           "wrist3_Link"}
    assert not links & arm
    assert links - {"tool_Link"} < {link.get("name") for link in whole.findall("link")}
    # Every joint joins two kept links (flange_joint, which carries the flange, is the vendor's tool joint).
    assert all(joint.find(end).get("link") in links for joint in part.findall("joint") for end in ("parent", "child"))
    assert sorted(movable) == ["finger_left_joint", "finger_right_joint"]
    hang = next(joint for joint in part.findall("joint") if joint.find("parent").get("link") == "tool_Link")
    assert hang.get("type") == "fixed" and hang.find("child").get("link") == "flange"
    assert hang.find("origin").get("xyz") == "0 0 0" and hang.find("origin").get("rpy") == "0 0 0"
    root = next(link for link in part.findall("link") if link.get("name") == "flange")
    assert root.find("inertial") is None  # KDL warns about a root with inertia


def test_the_command_line_prints_the_models_arm_and_refuses_another(capsys):
    from fr5_rl.ros.robot_description import main, robot_name, subtree_description

    with pytest.raises(ValueError, match="no link 'wrist4_Link'.*wrist3_Link"):
        subtree_description(URDF, "wrist4_Link")
    assert main(["--robot", "fr10", "--below-flange"]) == 0
    assert robot_name(capsys.readouterr().out) == "fr10"
    assert main(["--model", "models/reach"]) == 0
    trained_for = __import__("json").loads((REPO / "models" / "reach" / "meta.json").read_text())["robot"]
    assert robot_name(capsys.readouterr().out) == trained_for
    other = "fr10" if trained_for != "fr10" else "fr5"
    assert main(["--model", "models/reach", "--robot", other]) == 2
    assert f"trained for the {trained_for}, not the {other}" in capsys.readouterr().err
    assert main(["--robot", "fr99"]) == 2
    assert main(["--nonsense"]) == 2
    assert main(["--help"]) == 0
