"""Scenes of several objects on the table (issue #54): what a production line's cell holds.

A scene is 2-6 objects of ``object.variety``'s kinds (cylinders, boxes with square and oblong
tops) standing at any yaw in the placement region, drawn from a seed. By default their footprints
keep ``min_gap`` apart, so that a camera sees each one whole. ``touching`` sets some of them face
to face, which a detector must refuse rather than take for one object.

Pure numpy: the simulator builds the bodies (:meth:`fr5_rl.sim.camera.SimulatedCamera.set_objects`)
and the benches compare a detector's findings with :class:`SceneObject`. Settings:
``config/scenes.yaml`` (:class:`SceneSettings`).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import List, Optional, Sequence, Tuple, Union

import numpy as np

from .config import ConfigError, load_typed
from .draws import EpisodeDraws, draw_object
from .env_config import EnvConfig
from .objects import ObjectShape, quaternion_of_yaw, yaw_of


@dataclass(frozen=True)
class SceneSettings:
    """``config/scenes.yaml``.

    :param count: ``[fewest, most]`` objects in a scene.
    :param min_gap: m between two objects' footprints (their circumscribed circles: a bound that
        holds at every yaw).
    :param touching_share: share of the objects after the first set face to face against the one
        drawn before (0: none). A scene with any is for testing refusals.
    :param rectangular_min_difference: m: a box drawn oblong has its top's sides at least this far
        apart, so that "square" and "rectangular" are kinds a camera can tell (a 50 x 51 mm top is
        neither reliably).
    :param attempts: draws of a position before a scene gives up on one more object.
    """

    count: List[int]
    min_gap: float
    touching_share: float
    rectangular_min_difference: float
    attempts: int

    def check(self, source: str) -> None:
        """Refuse settings no scene can honour.

        :raises ConfigError: naming the bad key.
        """
        if len(self.count) != 2 or not 1 <= self.count[0] <= self.count[1]:
            raise ConfigError(f"{source}: 'count' must be [fewest, most] with 1 <= fewest <= most, got {self.count}")
        if self.min_gap < 0 or not 0.0 <= self.touching_share <= 1.0 or self.rectangular_min_difference < 0:
            raise ConfigError(f"{source}: 'min_gap' and 'rectangular_min_difference' must be >= 0 and "
                              f"'touching_share' in 0 ... 1")
        if self.attempts < 1:
            raise ConfigError(f"{source}: 'attempts' must be >= 1, got {self.attempts}")

    @classmethod
    def from_yaml(cls, path_or_name: Union[str, Path] = "scenes") -> "SceneSettings":
        """``config/scenes.yaml`` (or another file), typed and checked."""
        settings = load_typed(cls, path_or_name)
        settings.check(str(path_or_name))
        return settings


@dataclass(frozen=True)
class SceneObject:
    """One object standing on the table.

    :param shape: its kind and extents (m) along its own x, y, z (a box's longer top side first).
    :param position: its centre (m, base_link): x, y, and z half its height above the table top.
    :param yaw: rad, base_link, of its own x axis.
    :param mass: kg.
    :param touching: it was set against the object before it (``touching_share``).
    """

    shape: ObjectShape
    position: Tuple[float, float, float]
    yaw: float
    mass: float
    touching: bool = False

    @property
    def footprint_radius(self) -> float:
        """m: the radius of a circle around its footprint at any yaw."""
        return 0.5 * math.hypot(self.shape.size[0], self.shape.size[1]) if self.shape.kind == "box" \
            else 0.5 * self.shape.size[0]

    @property
    def quaternion(self) -> Tuple[float, float, float, float]:
        """(x, y, z, w): upright at its yaw."""
        return quaternion_of_yaw(self.yaw)

    @property
    def dims(self) -> Tuple[float, ...]:
        """The simulator's dimensions: (radius, height) of a cylinder, half extents of a box."""
        return self.shape.dims


@dataclass(frozen=True)
class StandingBody:
    """An object of a scene as it stands now (upright or not).

    :param shape: its kind and extents (m) along its own x, y, z.
    :param mass: kg.
    :param position: its centre (m, base_link).
    :param quaternion: (x, y, z, w), base_link.
    """

    shape: ObjectShape
    mass: float
    position: Tuple[float, float, float]
    quaternion: Tuple[float, float, float, float]

    @classmethod
    def of(cls, scene_object: SceneObject) -> "StandingBody":
        """A drawn object where it was drawn."""
        return cls(scene_object.shape, scene_object.mass, scene_object.position, scene_object.quaternion)

    @property
    def label(self) -> str:
        """``cylinder``, ``square box`` or ``rectangular box``."""
        return self.shape.label

    @property
    def up_z(self) -> float:
        """The z component of its own z axis in base_link (1: upright, 0: on its side)."""
        x, y, _, _ = self.quaternion
        return 1.0 - 2.0 * (x * x + y * y)

    def moved(self, position: Sequence[float], quaternion: Sequence[float]) -> "StandingBody":
        """The same object at a new pose."""
        return dataclasses.replace(self, position=tuple(float(v) for v in position),
                                   quaternion=tuple(float(v) for v in quaternion))


@dataclass(frozen=True)
class EpisodeScene:
    """One episode of a scene: the object to pick and set down, its goal, and the others.

    :param target: the object the task judges (standing upright).
    :param goal: where it goes: (x, y, yaw) in m, m, rad, base_link.
    :param others: every other object, where it stands.
    """

    target: StandingBody
    goal: Tuple[float, float, float]
    others: Tuple[StandingBody, ...]

    def draws_for(self, draws: EpisodeDraws) -> EpisodeDraws:
        """An episode's draws with this scene's target and goal in place of the drawn object
        and goal (every other draw, the arm's start and the chain's timing, as drawn)."""
        target = self.target
        return dataclasses.replace(
            draws, object_shape=target.shape.kind, object_dims=target.shape.dims, object_mass=target.mass,
            object_rest_z=float(target.position[2]), object_size_scale=1.0,
            object_xy=(float(target.position[0]), float(target.position[1])),
            object_yaw=yaw_of(target.quaternion), goal=tuple(float(v) for v in self.goal))


def draw_shape(rng: np.random.Generator, cfg: EnvConfig, settings: SceneSettings) -> Tuple[ObjectShape, float]:
    """One object as the environment draws it (:func:`fr5_rl.draws.draw_object`: ``object.variety``'s
    kinds and ranges, whether the variety is on in ``cfg`` or not), an oblong box's top sides at
    least ``rectangular_min_difference`` apart.

    :return: its shape and mass (kg).
    """
    kind, dims, mass = draw_object(rng, cfg, settings.rectangular_min_difference)
    return ObjectShape.from_dims(kind, dims), mass


def draw_scene(rng: np.random.Generator, cfg: EnvConfig, settings: SceneSettings,
               count: Optional[int] = None,
               region: Optional[Tuple[Sequence[float], Sequence[float]]] = None) -> List[SceneObject]:
    """A scene: ``count`` objects (default: drawn from ``settings.count``) in ``region``
    (``(low, high)`` corners, m, base_link; default ``object.region_*``).

    Each object is drawn at a uniform position and yaw until its footprint keeps ``min_gap`` from
    every other one (``attempts`` tries; then the scene has fewer objects). With
    ``touching_share``, an object may instead be set face to face against the one before it, at its
    yaw, along its x axis.

    :param rng: the scene's generator (a seed gives the same scene).
    :param cfg: the environment's configuration (the table top, the region, the variety).
    :return: the objects, in the order drawn.
    """
    if count is None:
        count = int(rng.integers(settings.count[0], settings.count[1] + 1))
    low, high = region if region is not None else (cfg.object.region_low, cfg.object.region_high)
    low, high = np.asarray(low, dtype=float), np.asarray(high, dtype=float)
    table_top = cfg.table.top_height
    scene: List[SceneObject] = []
    for _ in range(count):
        shape, mass = draw_shape(rng, cfg, settings)
        placed = None
        if scene and rng.uniform() < settings.touching_share:
            placed = _against(scene[-1], shape, mass, table_top, low, high)
        for _ in range(settings.attempts):
            if placed is not None:
                break
            xy = rng.uniform(low, high)
            candidate = SceneObject(shape, (float(xy[0]), float(xy[1]), table_top + 0.5 * shape.size[2]),
                                    float(rng.uniform(-math.pi, math.pi)), mass)
            if all(_gap(candidate, other) >= settings.min_gap for other in scene):
                placed = candidate
        if placed is not None:
            scene.append(placed)
    return scene


def _gap(a: SceneObject, b: SceneObject) -> float:
    """m between two footprints' circumscribed circles (negative: they may overlap)."""
    return math.hypot(a.position[0] - b.position[0], a.position[1] - b.position[1]) \
        - a.footprint_radius - b.footprint_radius


def _against(other: SceneObject, shape: ObjectShape, mass: float, table_top: float,
             low: np.ndarray, high: np.ndarray) -> Optional[SceneObject]:
    """``shape`` set face to face against ``other``, at its yaw, along its x axis; None if that
    falls outside the region."""
    distance = 0.5 * other.shape.size[0] + 0.5 * shape.size[0]
    x = other.position[0] + distance * math.cos(other.yaw)
    y = other.position[1] + distance * math.sin(other.yaw)
    if not (low[0] <= x <= high[0] and low[1] <= y <= high[1]):
        return None
    return SceneObject(shape, (x, y, table_top + 0.5 * shape.size[2]), other.yaw, mass, touching=True)

