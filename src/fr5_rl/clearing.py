"""Clearing the table (issue #54): which object is next, and where it goes.

One rule for everyone who has to agree on it: the detector node's selection
(:class:`fr5_rl.perception.target_selection.SceneTargetTracker`) applies it to what the camera
measured, the simulator's clearing run (:mod:`fr5_rl.scene_episodes`) to the truth. Pure Python;
settings in ``config/clearing.yaml`` (:class:`ClearingSettings`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import List, Optional, Sequence, Tuple, TypeVar, Union

from .config import ConfigError, load_typed

RULES = ("nearest", "kind", "id")
KINDS = ("cylinder", "square box", "rectangular box")


@dataclass(frozen=True)
class ClearingSettings:
    """``config/clearing.yaml`` (positions in the table frame, m; yaw in rad).

    :param pick_area_low: ``[x, y]`` corner of where a scene's objects stand.
    :param pick_area_high: the opposite corner.
    :param drop_area_low: ``[x, y]`` corner of the drop area: an object whose centre lies there
        has been placed and is never chosen again.
    :param drop_area_high: the opposite corner.
    :param drop_slots: the goals ``[x, y, yaw]``, filled in this order.
    :param rule: how the next object is chosen (:data:`RULES`).
    :param reference_xy: ``nearest`` is nearest to this point (the robot's base).
    :param kind_order: rule ``kind``: these kinds first, in this order (others after them).
    :param count: ``[fewest, most]`` objects in a scene to clear.
    :param min_gap: m between two objects' footprints in such a scene.
    """

    pick_area_low: List[float]
    pick_area_high: List[float]
    drop_area_low: List[float]
    drop_area_high: List[float]
    drop_slots: List[List[float]]
    rule: str
    reference_xy: List[float]
    kind_order: List[str]
    count: List[int]
    min_gap: float

    def check(self, source: str) -> None:
        """:raises ConfigError: naming the key no clearing run can honour."""
        for name in ("pick_area", "drop_area"):
            low, high = getattr(self, f"{name}_low"), getattr(self, f"{name}_high")
            if len(low) != 2 or len(high) != 2 or not all(a < b for a, b in zip(low, high)):
                raise ConfigError(f"{source}: '{name}_low' and '{name}_high' must be [x, y] with low < high")
        if _overlap(self.pick_area_low, self.pick_area_high, self.drop_area_low, self.drop_area_high):
            raise ConfigError(f"{source}: the pick area and the drop area overlap: a placed object would be picked again")
        if not self.drop_slots or any(len(slot) != 3 or not self.in_drop_area(slot[:2]) for slot in self.drop_slots):
            raise ConfigError(f"{source}: 'drop_slots' must list [x, y, yaw] goals inside the drop area")
        check_rule(self.rule, source)
        unknown = [kind for kind in self.kind_order if kind not in KINDS]
        if unknown:
            raise ConfigError(f"{source}: 'kind_order' has {unknown[0]!r}; the kinds are {', '.join(KINDS)}")
        if len(self.count) != 2 or not 1 <= self.count[0] <= self.count[1] <= len(self.drop_slots):
            raise ConfigError(f"{source}: 'count' must be [fewest, most], 1 <= fewest <= most <= the "
                              f"{len(self.drop_slots)} drop slots, got {self.count}")
        if self.min_gap < 0 or len(self.reference_xy) != 2:
            raise ConfigError(f"{source}: 'min_gap' must be >= 0 and 'reference_xy' [x, y]")

    @classmethod
    def from_yaml(cls, path_or_name: Union[str, Path] = "clearing") -> "ClearingSettings":
        """``config/clearing.yaml`` (or another file), typed and checked."""
        return load_typed(cls, path_or_name)

    def in_drop_area(self, xy: Sequence[float]) -> bool:
        """Whether a centre at ``xy`` (m) lies in the drop area (placed)."""
        return _inside(xy, self.drop_area_low, self.drop_area_high)

    def in_pick_area(self, xy: Sequence[float], margin: float = 0.0) -> bool:
        """Whether a centre at ``xy`` (m) lies in the pick area, grown by ``margin`` (m)."""
        return _inside(xy, [v - margin for v in self.pick_area_low], [v + margin for v in self.pick_area_high])


def check_rule(rule: str, source: str = "selection") -> None:
    """:raises ConfigError: ``rule`` is none of :data:`RULES`."""
    if rule not in RULES:
        raise ConfigError(f"{source}: rule {rule!r} is none of {', '.join(RULES)}")


Candidate = TypeVar("Candidate")


def choose_next(candidates: Sequence[Tuple[Candidate, str, Sequence[float]]], rule: str,
                reference_xy: Sequence[float], kind_order: Sequence[str] = KINDS,
                wanted_kind: Optional[str] = None) -> Optional[Candidate]:
    """The object to pick next.

    :param candidates: ``(what, kind, xy)`` of each object that may be picked (not yet placed):
        ``what`` is returned for the one chosen; ``xy`` its centre (m, table frame).
    :param rule: ``nearest``: nearest to ``reference_xy``; ``kind``: the first of ``kind_order``
        (or ``wanted_kind`` alone) that is there, the nearest of that kind. Rule ``id`` is the
        caller's (a track id names the object itself).
    :param reference_xy: m, table frame.
    :param wanted_kind: rule ``kind``: only this kind (None: ``kind_order``).
    :return: the chosen ``what``; None when no candidate fits (none left, or none of the kind).
    """
    check_rule(rule)
    if rule == "id":
        raise ValueError("choose_next: rule 'id' names its object; look it up by id instead")

    def distance(entry) -> float:
        return math.hypot(entry[2][0] - reference_xy[0], entry[2][1] - reference_xy[1])

    pool = list(candidates)
    if rule == "kind":
        order = [wanted_kind] if wanted_kind is not None else list(kind_order)
        for kind in order:
            of_kind = [entry for entry in pool if entry[1] == kind]
            if of_kind:
                return min(of_kind, key=distance)[0]
        if wanted_kind is not None:
            return None
        # Kinds kind_order does not name come after those it does.
    return min(pool, key=distance)[0] if pool else None


def _inside(xy: Sequence[float], low: Sequence[float], high: Sequence[float]) -> bool:
    return low[0] <= xy[0] <= high[0] and low[1] <= xy[1] <= high[1]


def _overlap(low_a, high_a, low_b, high_b) -> bool:
    return all(low_a[i] < high_b[i] and low_b[i] < high_a[i] for i in range(2))
