"""Clearing the table in the simulator: a scene of several objects, one episode per object
(issue #54).

:class:`TableClearing` is what the simulator node (and the benches) run when a cell is to clear
a table rather than handle one object at a time:

- a scene of ``config/clearing.yaml`` ``count`` objects stands in its pick area (drawn from the
  run's seed and the scene's number: :func:`fr5_rl.scenes.draw_scene`);
- each episode's object is the cell's choice when the caller has one (the detector's ``~next``),
  else the clearing rule's on the true poses (:func:`fr5_rl.clearing.choose_next`, the rule the
  detector applies to what it measures); its goal is the next free drop slot; the others stand
  around it, where the last episode left them;
- after the episode, a neighbour the arm knocked over (tilted past ``place.knocked_over_angle_deg``)
  fails it (``knocked_neighbour``). An object the episode lost for the cell (knocked over,
  carried into the drop area instead of the one judged, pushed out of reach, off the table) gets a
  record of its own, and it and an object the episode did not place are taken off the table at
  once, as an operator would. So every object of a scene gets exactly one record;
- once no object is left to pick, the next scene stands at once (before the cell is asked).

Only the task's own object is judged by the task; the rest is this module's.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from .clearing import ClearingSettings, choose_next
from .episode import Episode
from .scenes import EpisodeScene, SceneSettings, StandingBody, draw_scene
from .tasks import EpisodeVerdict

CHOICE_GATE = 0.03  # m: the cell's choice and the true object it names (the detector measures to ~2 mm)


def scene_generator(seed: int, scene: int) -> np.random.Generator:
    """The generator scene number ``scene`` (0, 1, ...) of a run seeded ``seed`` is drawn from
    (apart from the episodes' own seeds)."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), int(scene), 54]))


def scene_sizes(episode: Episode, settings: ClearingSettings, seed: int, scenes: int, first_scene: int = 0) -> List[int]:
    """How many objects each of ``scenes`` scenes of a run holds, from ``first_scene`` on (a run of
    them has that many episodes)."""
    clearing = TableClearing(episode, settings, seed)
    return [len(clearing.draw(number)) for number in range(first_scene, first_scene + scenes)]


class TableClearing:
    """The scenes of a clearing run on one simulated cell, episode after episode.

    :param episode: the simulated cell (its configuration: table, region, ``place`` limits).
    :param settings: ``config/clearing.yaml``.
    :param seed: the run's seed (scene k is drawn from :func:`scene_generator`).
    :param first_scene: the first scene's number (to replay one of a run).
    """

    def __init__(self, episode: Episode, settings: ClearingSettings, seed: int, first_scene: int = 0) -> None:
        self.cfg, self.settings, self.seed = episode.cfg, settings, seed
        self.scene_settings = dataclasses.replace(SceneSettings.from_yaml(), count=list(settings.count),
                                                  min_gap=settings.min_gap, touching_share=0.0)
        self.upright_cos = math.cos(math.radians(self.cfg.place.knocked_over_angle_deg))
        self.first_scene = first_scene
        self.scene_number = first_scene - 1
        self.bodies: List[StandingBody] = []  # every object on the table now, the episode's target first
        self.placed: List[bool] = []  # by body: set down in the drop area by an episode
        self.slot = 0  # the next free drop slot
        self.object_in_scene = 0  # episodes (records) of this scene so far
        self.extra_records: List[Dict[str, Any]] = []  # objects lost by an episode: a record each
        self.chosen_by = "rule"  # who chose the current episode's object: the cell (its detector) or the rule

    def draw(self, number: int) -> List[StandingBody]:
        """Scene ``number``'s objects, standing where they were drawn."""
        low, high = self.settings.pick_area_low, self.settings.pick_area_high
        return [StandingBody.of(item) for item in draw_scene(scene_generator(self.seed, number), self.cfg,
                                                               self.scene_settings, region=(low, high))]

    def pickable(self) -> List[int]:
        """Indices of the objects still to pick: upright and not in the drop area."""
        return [i for i, body in enumerate(self.bodies)
                if not self.placed[i] and not self.settings.in_drop_area(body.position[:2])
                and body.up_z >= self.upright_cos]

    def next_scene(self, chosen_xy: Optional[Sequence[float]] = None) -> EpisodeScene:
        """The next episode: the next object, the next free slot, the others around. A scene with
        nothing left to pick gives way to the next one.

        :param chosen_xy: where the cell's own choice stands (m, base_link: the detector's
            ``~next`` answer): the object to pick within
            ``CHOICE_GATE`` of it is the one judged. None, or none there: the clearing rule on the
            true poses (the camera may not see the one the rule names: the arm, or an object in
            front of it, hides it).
        """
        left = self.pickable()
        if not left:
            self._new_scene()
            left = self.pickable()
        settings = self.settings
        index = None
        if chosen_xy is not None:
            near = [(math.hypot(self.bodies[i].position[0] - chosen_xy[0], self.bodies[i].position[1] - chosen_xy[1]), i)
                    for i in left]
            distance, nearest = min(near)
            index = nearest if distance <= CHOICE_GATE else None
        self.chosen_by = "cell" if index is not None else "rule"
        if index is None:
            index = choose_next([(i, self.bodies[i].label, self.bodies[i].position[:2]) for i in left],
                                settings.rule if settings.rule != "id" else "nearest", settings.reference_xy,
                                settings.kind_order)
        # The target first: after the episode, the episode's object and the rest come back in this order.
        order = [index] + [i for i in range(len(self.bodies)) if i != index]
        self.bodies = [self.bodies[i] for i in order]
        self.placed = [self.placed[i] for i in order]
        goal = tuple(settings.drop_slots[min(self.slot, len(settings.drop_slots) - 1)])
        return EpisodeScene(self.bodies[0], goal, tuple(self.bodies[1:]))

    def finish(self, episode: Episode, verdict: EpisodeVerdict) -> Tuple[EpisodeVerdict, Dict[str, Any]]:
        """After the episode: where everything ended, which neighbours were knocked over, and
        what stays on the table.

        :return: the verdict (a success that knocked a neighbour over fails as
            ``knocked_neighbour``; a failure that left another object in the drop area, as
            ``other_object_placed``) and the episode record's clearing fields (``scene``,
            ``object_in_scene``, ``chosen_by``, ``knocked``: labels). Every other object the episode
            lost for the cell (knocked over, pushed into the drop area or off the table) gets a
            record of its own in :attr:`extra_records`, and is taken off the table.
        """
        target = episode.object_pose()
        poses = [target] + list(episode.neighbour_poses())
        before = self.bodies
        self.bodies = [body.moved(pose.position, pose.quaternion) for body, pose in zip(before, poses)]
        knocked = [i for i in range(1, len(self.bodies))
                   if before[i].up_z >= self.upright_cos > self.bodies[i].up_z]
        lost = {i: self._lost(i) for i in range(1, len(self.bodies)) if not self.placed[i]}
        lost = {i: why for i, why in lost.items() if why is not None}
        if verdict.success and knocked:
            verdict = verdict._replace(success=False, failure="knocked_neighbour")
        elif not verdict.success and any(why == "other_object_placed" for why in lost.values()):
            verdict = verdict._replace(failure="other_object_placed")
        fields = {"scene": self.scene_number, "object_in_scene": self.object_in_scene, "chosen_by": self.chosen_by,
                  "knocked": [self.bodies[i].label for i in knocked]}
        self.object_in_scene += 1
        placed = verdict.success or (verdict.failure == "knocked_neighbour"
                                     and self.settings.in_drop_area(self.bodies[0].position[:2]))
        if placed:
            self.placed[0] = True
            self.slot += 1
        self.extra_records = []
        for i, why in lost.items():
            body = self.bodies[i]
            self.extra_records.append({
                "success": False, "failure": why, "steps": 0, "scene": self.scene_number,
                "object_in_scene": self.object_in_scene, "object": body.label,
                "object_x": round(float(body.position[0]), 4), "object_y": round(float(body.position[1]), 4)})
            self.object_in_scene += 1
        # What the episode did not place, and what it lost, an operator takes away, now: the
        # camera must not show them to the cell that chooses the next object.
        gone = set(lost) | (set() if placed else {0})
        episode.take_off_table([i - 1 for i in lost], 0 in gone)
        keep = [i for i in range(len(self.bodies)) if i not in gone]
        self.bodies = [self.bodies[i] for i in keep]
        self.placed = [self.placed[i] for i in keep]
        if not self.pickable():
            # The scene is cleared: the next one stands at once, so that the camera shows it to the
            # cell before the cell is asked which object is next.
            self._new_scene()
            episode.show_scene([(body.shape, body.mass, body.position, body.quaternion) for body in self.bodies])
        return verdict, fields

    def show_first_scene(self, episode: Episode) -> None:
        """Before the run's first episode: its scene stands on the table, no object chosen yet
        (a cell's camera then shows it to the cell, which is asked what is next)."""
        if self.scene_number < self.first_scene:
            self._new_scene()
            episode.show_scene([(body.shape, body.mass, body.position, body.quaternion) for body in self.bodies])

    def _new_scene(self) -> None:
        self.scene_number += 1
        self.bodies = self.draw(self.scene_number)
        self.placed = [False] * len(self.bodies)
        self.slot, self.object_in_scene = 0, 0

    def _lost(self, index: int) -> Optional[str]:
        """Why an object not placed can no longer be picked, or None: knocked over, carried into
        the drop area by the episode (the cell took another object than the one judged),
        pushed out of the placement region, or off the table."""
        body = self.bodies[index]
        if body.position[2] < self.cfg.table.top_height:
            return "fell_off_the_table"
        if body.up_z < self.upright_cos:
            return "knocked_over"
        if self.settings.in_drop_area(body.position[:2]):
            return "other_object_placed"
        region = self.cfg.object
        margin = self.cfg.place.out_of_reach_margin
        x, y = body.position[:2]
        if not (region.region_low[0] - margin <= x <= region.region_high[0] + margin
                and region.region_low[1] - margin <= y <= region.region_high[1] + margin):
            return "pushed_away"
        return None
