"""Clearing the table in the simulator (fr5_rl.scene_episodes): a scene of several objects, one
episode per object, in the real simulated cell (PyBullet): the target by the clearing rule, its
goal the next drop slot, the others standing around it where they were; a placed object stays,
one not placed and one knocked over are taken off the table, and every object gets one record."""
import math

import numpy as np
import pytest

from fr5_rl.clearing import ClearingSettings, choose_next
from fr5_rl.episode import Episode
from fr5_rl.scene_episodes import TableClearing, scene_sizes
from fr5_rl.tasks import EpisodeVerdict

SETTINGS = ClearingSettings.from_yaml()


@pytest.fixture(scope="module")
def episode():
    sim = Episode.build("place")
    yield sim
    sim.close()


def verdict(success: bool, failure=None) -> EpisodeVerdict:
    return EpisodeVerdict(success, failure, True, False, 100, None)


def first_episode(sim: Episode, scene_seed: int, episode_seed: int):
    """A clearing run's first episode started: ``(clearing, its scene, objects in it)``."""
    clearing = TableClearing(sim, SETTINGS, scene_seed)
    first = clearing.next_scene()
    sim.start(episode_seed, {"scene": first})
    return clearing, first, 1 + len(first.others)


def set_down_at_goal(sim: Episode, scene) -> None:
    """The episode's object set down at its goal, upright at the goal's yaw, as a policy would."""
    x, y, yaw = scene.goal
    sim.plant.place_object((x, y), yaw)


def settle(sim: Episode, periods: int = 25) -> None:
    """Let physics run with the arm held where it stands, the gripper open."""
    for _ in range(periods):
        sim.advance_period(sim.joint_positions(), sim.robot_spec.max_opening_width)


def test_scenes_are_drawn_from_the_seed_in_the_pick_area(episode):
    sizes = scene_sizes(episode, SETTINGS, 11, 6)
    assert sizes == scene_sizes(episode, SETTINGS, 11, 6)
    assert all(SETTINGS.count[0] <= size <= SETTINGS.count[1] for size in sizes)
    assert sizes != scene_sizes(episode, SETTINGS, 12, 6)  # another seed, other scenes
    clearing = TableClearing(episode, SETTINGS, 11)
    for body in clearing.draw(0):
        assert SETTINGS.in_pick_area(body.position[:2]) and body.up_z == pytest.approx(1.0)


def test_each_episode_picks_by_the_rule_and_the_others_stand_around_it(episode):
    clearing = TableClearing(episode, SETTINGS, 21)
    scene = clearing.next_scene()
    drawn = [scene.target, *scene.others]
    expected = choose_next([(i, body.label, body.position[:2]) for i, body in enumerate(drawn)], "nearest",
                           SETTINGS.reference_xy)
    assert expected == 0 and scene.goal == tuple(SETTINGS.drop_slots[0])
    episode.start(5, {"scene": scene})
    assert episode.object_pose().position == pytest.approx(scene.target.position, abs=1e-6)
    assert episode.draws.goal == scene.goal
    assert episode.scene().object_description == scene.target.shape
    poses = episode.neighbour_poses()
    assert [pose.position for pose in poses] == [pytest.approx(other.position, abs=1e-6) for other in scene.others]
    assert episode.neighbour_shapes == [other.shape for other in scene.others]
    settle(episode)
    # Standing still, nothing falls: the same scene, one object picked.
    for pose, other in zip(episode.neighbour_poses(), scene.others):
        assert pose.position == pytest.approx(other.position, abs=2e-3)
    # A plain episode after it has the object alone.
    episode.start(6)
    assert episode.neighbour_poses() == []


def test_a_placed_object_stays_and_the_next_goal_is_the_next_slot(episode):
    clearing, first, count = first_episode(episode, 31, 7)
    set_down_at_goal(episode, first)
    settle(episode)
    outcome, fields = clearing.finish(episode, verdict(True))
    assert outcome.success and fields == {"scene": 0, "object_in_scene": 0, "chosen_by": "rule", "knocked": []}
    second = clearing.next_scene()
    assert second.goal == tuple(SETTINGS.drop_slots[1])
    assert len(second.others) == count - 1  # the placed one is among them, in the drop area
    assert sum(SETTINGS.in_drop_area(other.position[:2]) for other in second.others) == 1
    assert not SETTINGS.in_drop_area(second.target.position[:2])


def test_an_object_not_placed_is_taken_off_the_table(episode):
    clearing, first, count = first_episode(episode, 41, 8)
    settle(episode, 5)
    clearing.finish(episode, verdict(False, "timeout"))
    assert episode.object_pose().position[2] < -1.0  # off the table at once: the camera must not see it
    second = clearing.next_scene()
    assert 1 + len(second.others) == count - 1
    assert second.goal == tuple(SETTINGS.drop_slots[0])  # no slot was used


def test_a_neighbour_knocked_over_fails_the_pick_and_gets_a_record_of_its_own(episode):
    clearing, first, count = first_episode(episode, 51, 9)
    set_down_at_goal(episode, first)
    # The arm knocked a neighbour onto its side.
    body = episode.plant._neighbours[0][0]
    other = first.others[0]
    lying = (math.sin(math.pi / 4.0), 0.0, 0.0, math.cos(math.pi / 4.0))  # 90 degrees about x
    episode.plant.world.place_body(body, (other.position[0], other.position[1], 0.05), lying)
    settle(episode, 10)
    outcome, fields = clearing.finish(episode, verdict(True))
    assert not outcome.success and outcome.failure == "knocked_neighbour"
    assert fields["knocked"] == [other.label]
    assert [record["failure"] for record in clearing.extra_records] == ["knocked_over"]
    assert clearing.extra_records[0]["object_in_scene"] == 1
    assert len(episode.neighbour_poses()) == count - 2  # the knocked one gone from the world at once
    # The placed object stays; the knocked one is gone; the rest stand.
    second = clearing.next_scene()
    assert 1 + len(second.others) == count - 1
    assert second.goal == tuple(SETTINGS.drop_slots[1])


def test_after_the_last_object_the_next_scene_comes(episode):
    clearing = TableClearing(episode, SETTINGS, 61)
    sizes = scene_sizes(episode, SETTINGS, 61, 2)
    for _ in range(sizes[0]):
        scene = clearing.next_scene()
        assert clearing.scene_number == 0
        episode.start(10, {"scene": scene})
        clearing.finish(episode, verdict(False, "timeout"))
        assert clearing.scene_number == 0 or len(episode.neighbour_poses()) == sizes[1]
    # The next scene stands as soon as the last one is cleared: the camera shows it to the cell
    # before it is asked which object is next.
    assert clearing.scene_number == 1 and len(episode.neighbour_poses()) == sizes[1]
    assert episode.object_pose().position[2] < -1.0
    scene = clearing.next_scene()
    assert clearing.scene_number == 1 and 1 + len(scene.others) == sizes[1]
    assert np.all([SETTINGS.in_pick_area(body.position[:2]) for body in (scene.target, *scene.others)])


def test_a_tilted_target_is_never_chosen(episode):
    clearing = TableClearing(episode, SETTINGS, 71)
    scene = clearing.next_scene()
    tilted = clearing.bodies[1].moved(clearing.bodies[1].position, (0.5, 0.0, 0.0, math.sqrt(0.75)))
    clearing.bodies[1] = tilted
    assert 1 not in clearing.pickable() and 0 in clearing.pickable() and scene.target is clearing.bodies[0]


def test_the_object_the_cell_chose_is_the_one_judged(episode):
    clearing = TableClearing(episode, SETTINGS, 81)
    bodies = clearing.draw(0)
    by_rule = clearing.next_scene().target
    other = next(body for body in bodies if body.position != by_rule.position)
    clearing = TableClearing(episode, SETTINGS, 81)
    chosen = clearing.next_scene(chosen_xy=(other.position[0] + 0.01, other.position[1] - 0.01))
    assert chosen.target.position == other.position and clearing.chosen_by == "cell"
    # A choice that names no object (the one just placed, or nothing there): the rule.
    clearing = TableClearing(episode, SETTINGS, 81)
    assert clearing.next_scene(chosen_xy=SETTINGS.drop_slots[0][:2]).target.position == by_rule.position
    assert clearing.chosen_by == "rule"


def test_another_object_carried_to_the_drop_area_fails_the_pick_and_is_counted(episode):
    clearing, first, count = first_episode(episode, 91, 11)
    body = episode.plant._neighbours[0][0]
    x, y, _ = first.goal
    episode.plant.world.place_body(body, (x, y, first.others[0].position[2]), (0.0, 0.0, 0.0, 1.0))
    settle(episode, 10)
    outcome, _ = clearing.finish(episode, verdict(False, "timeout"))
    assert outcome.failure == "other_object_placed"
    assert [record["failure"] for record in clearing.extra_records] == ["other_object_placed"]
    # Neither the one judged nor the one carried off stays to be picked: one record each.
    assert 1 + len(clearing.next_scene().others) == count - 2


def test_the_first_scene_stands_before_the_first_episode():
    fresh = Episode.build("place")
    try:
        clearing = TableClearing(fresh, SETTINGS, 101)
        clearing.show_first_scene(fresh)
        drawn = clearing.draw(0)
        assert [pose.position for pose in fresh.neighbour_poses()] == [pytest.approx(b.position) for b in drawn]
        assert fresh.object_pose().position[2] < -1.0  # no object chosen yet
        settle(fresh, 5)
        scene = clearing.next_scene()
        assert clearing.scene_number == 0 and 1 + len(scene.others) == len(drawn)
    finally:
        fresh.close()
