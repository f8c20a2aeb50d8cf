"""The dry run's ghost robot: the package URDF with every link renamed, hung from the real base."""
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from fr5_rl.ros.ghost_robot import prefixed_description

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
