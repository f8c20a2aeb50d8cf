"""Every per-episode random draw, in one function and one fixed order.

:func:`draw_episode` makes all of an episode's draws from the environment's generator before
anything is built from them: the object (size, mass, friction, place, yaw), the arm (damping,
start), the physics step, and the control chain's delays (latency, in-period timing, the
driver's response, the bridged gripper's phases, the camera's timing, the motion guard). The
order is the environment's contract with every seed: a draw made only when its feature is
configured keeps the episodes of configurations without it.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Sequence, Tuple

import numpy as np

from .config import ConfigError, RobotSpec
from .env_config import EnvConfig


@dataclass(frozen=True)
class TargetTiming:
    """The camera's timing of one episode (:class:`~fr5_rl.observation.DelayedTarget`).

    :param latency: s from the moment a frame shows to its pose arriving.
    :param frame_period: s between frames.
    :param phase: s of the first frame after the reset.
    """

    latency: float
    frame_period: float
    phase: float


@dataclass(frozen=True)
class EpisodeDraws:
    """One episode's draws (see :func:`draw_episode`); units SI, positions in base_link.

    :param perturbed: the randomisation applies this episode (not a plain one).
    :param object_shape: ``cylinder`` or ``box``.
    :param object_dims: (radius, height) of a cylinder, (half_extent,) of the configured cube, or
        (half_x, half_y, half_z) of a drawn box with ``half_x >= half_y`` (m).
    :param object_rest_z: z (m, base_link) of the object's centre standing on the table.
    :param object_size_scale: the factor the configured size was scaled by.
    :param object_mass: kg. :param object_friction: lateral friction coefficient.
    :param object_xy: where the object stands (m). :param object_yaw: its yaw (rad).
    :param start_joint_positions: the arm's start (rad, j1 .. j6), before clipping to the limits.
    :param joint_damping: N*m*s/rad on every arm joint.
    :param physics_dt: s per physics step.
    :param action_latency_steps: whole control periods the arm's command lags.
    :param gripper_latency_steps: the gripper's own lag (periods); None: the arm's.
    :param observation_noise_std: std of the noise on joints (rad) and object position (m).
    :param command_delay_s: (low, high) s the previous command stands into each period.
    :param observation_age_s: (low, high) s before the period's end the joint state is measured.
    :param response_time_constants: the driver's lag per joint (s), or None: none this episode.
    :param bridge_phases: the bridged gripper's (call, read, zero-debounce) phases (s), or None:
        the gripper is driven directly this episode.
    :param target: the camera's timing, or None: the object is seen as it is.
    :param guard: the policy node's motion guard limits this episode's commands.
    :param goal: where the object is to be set down: (x, y) in m, base_link, and its yaw in rad
        (the place task's; None for the others).
    """

    perturbed: bool
    object_shape: str
    object_dims: Tuple[float, ...]
    object_rest_z: float
    object_size_scale: float
    object_mass: float
    object_friction: float
    object_xy: Tuple[float, float]
    object_yaw: float
    start_joint_positions: Tuple[float, ...]
    joint_damping: float
    physics_dt: float
    action_latency_steps: int
    gripper_latency_steps: Optional[int]
    observation_noise_std: float
    command_delay_s: Tuple[float, float]
    observation_age_s: Tuple[float, float]
    response_time_constants: Optional[Tuple[float, ...]]
    bridge_phases: Optional[Tuple[float, float, float]]
    target: Optional[TargetTiming]
    guard: bool
    goal: Optional[Tuple[float, float, float]] = None

    @property
    def in_period_timing(self) -> bool:
        """The period has inner timing: a delayed command, an early measurement or a response."""
        return self.command_delay_s[1] > 0.0 or self.observation_age_s[1] > 0.0 or self.response_time_constants is not None


def draw_episode(rng: np.random.Generator, cfg: EnvConfig, robot: RobotSpec, task: str, physics_dt: float,
                 bridge_periods: Optional[Tuple[float, float, float]], guard_available: bool,
                 object_xy: Optional[Sequence[float]] = None) -> EpisodeDraws:
    """Every random draw of one episode, in the environment's fixed order.

    :param rng: the environment's generator (gymnasium's ``np_random``).
    :param cfg: the configuration (``object``, ``randomisation``, the task's start noise).
    :param robot: the arm (home pose).
    :param task: the task's name (its ``start_joint_noise``).
    :param physics_dt: the task's configured physics step (s), kept unless drawn.
    :param bridge_periods: the bridged gripper's (call period, read period, zero debounce) in s,
        or None where the configuration puts no gripper behind the bridge.
    :param guard_available: the configuration runs the motion guard in some episodes.
    :param object_xy: the object's place (m, base_link) given by the caller; None: drawn.
    """
    obj, rnd = cfg.object, cfg.randomisation
    # The object's kind and nominal size: drawn only with object.variety on (first, so that the
    # draws after it are made as in every other configuration).
    shape, nominal_dims, nominal_mass = draw_object(rng, cfg) if obj.variety.enabled else (obj.shape, None, obj.mass)
    on = rnd.enabled
    if on and rnd.plain_episode_share > 0.0:  # drawn only when asked for: other configurations keep their episodes
        on = bool(rng.uniform() >= rnd.plain_episode_share)
    size = rng.uniform(*rnd.object_size_scale) if on else 1.0
    mass = nominal_mass * (rng.uniform(*rnd.object_mass_scale) if on else 1.0)
    friction = obj.lateral_friction * (rng.uniform(*rnd.friction_scale) if on else 1.0)
    if nominal_dims is not None:
        dims = tuple(value * size for value in nominal_dims)
        rest_z = cfg.table.top_height + (dims[1] / 2.0 if shape == "cylinder" else dims[2])
    else:  # the configured object, as every model before object.variety was trained on
        dims = (obj.radius * size, obj.height * size) if obj.shape == "cylinder" else (obj.half_extent * size,)
        rest_z = cfg.object_rest_z(size)
    damping = rng.uniform(*rnd.joint_damping) if on else 0.0
    # The simulated position controller tracks differently at other physics steps: drawing the
    # step per episode keeps a policy from relying on one simulator's exact response.
    choices = rnd.physics_dt_choices
    drawn_physics_dt = float(rng.choice(choices)) if on and choices else physics_dt
    lo, hi = rnd.action_latency_steps
    latency = int(rng.integers(lo, hi + 1)) if on else 0
    # Without timing_share, every perturbed episode has the in-period timing and every plain one
    # none: a policy then reads "no jitter" as "no latency" and rushes into whole-step latency alone.
    timing = on
    if on and rnd.timing_share < 1.0:
        timing = bool(rng.uniform() < rnd.timing_share)
    response = None
    if timing and any(tau > 0.0 for tau in rnd.response_time_constant_s):
        response = tuple(rnd.response_time_constant_s)
    bridge = None
    if on and bridge_periods is not None and rng.uniform() < rnd.gripper_bridge_share:
        call_period, read_period, zero_debounce = bridge_periods
        bridge = (float(rng.uniform(0.0, call_period)), float(rng.uniform(0.0, read_period)),
                  float(rng.uniform(0.0, zero_debounce)))
    target = None
    if on and rnd.target_share > 0.0 and rng.uniform() < rnd.target_share:
        frame_period = 1.0 / rnd.target_rate_hz
        target = TargetTiming(float(rng.uniform(*rnd.target_latency_s)), frame_period,
                              float(rng.uniform(0.0, frame_period)))
        if rnd.target_action_latency_steps is not None:  # drawn only when set
            lo, hi = rnd.target_action_latency_steps
            latency = int(rng.integers(lo, hi + 1))
    gripper_latency = None
    if on and rnd.gripper_latency_steps is not None:  # drawn only when set
        lo, hi = rnd.gripper_latency_steps
        gripper_latency = int(rng.integers(lo, hi + 1))
    # The policy node's motion guard runs on every chain, plain episodes too.
    guard = bool(guard_available and rng.uniform() < rnd.guard_share)

    # The place: drawn after the chain's draws (the order every seed was made with).
    if object_xy is not None:
        xy = np.asarray(object_xy, dtype=float)
    else:
        xy = rng.uniform(np.asarray(obj.region_low), np.asarray(obj.region_high))
        # Drawn only when on, so that with the focus off a seed places the same object as before.
        if rnd.enabled and rnd.placement_focus_share > 0.0 and rng.uniform() < rnd.placement_focus_share:
            xy = rng.uniform(np.asarray(rnd.placement_focus_low), np.asarray(rnd.placement_focus_high))
    yaw = float(rng.uniform(-np.pi, np.pi))
    noise = cfg.task(task).start_joint_noise
    start = robot.home_joint_positions + rng.uniform(-noise, noise, 6)
    # The goal: drawn last, and only by a task that has one, so every other task's draws stay.
    goal = draw_goal(rng, cfg, xy) if task == "place" else None
    return EpisodeDraws(
        perturbed=on, object_shape=shape, object_dims=dims, object_rest_z=rest_z, object_size_scale=size, object_mass=mass, object_friction=friction,
        object_xy=(float(xy[0]), float(xy[1])), object_yaw=yaw, start_joint_positions=tuple(start.tolist()),
        joint_damping=damping, physics_dt=drawn_physics_dt, action_latency_steps=latency,
        gripper_latency_steps=gripper_latency, observation_noise_std=rnd.observation_noise_std if on else 0.0,
        command_delay_s=tuple(rnd.command_delay_s) if timing else (0.0, 0.0),
        observation_age_s=tuple(rnd.observation_age_s) if timing else (0.0, 0.0),
        response_time_constants=response, bridge_phases=bridge, target=target, guard=guard, goal=goal,
    )


def draw_place(rng: np.random.Generator, cfg: EnvConfig) -> Tuple[Tuple[float, float], float]:
    """Another place and yaw for the object, uniform over ``object.region_*`` (a redraw where
    the first place lies too close to an arm that stays where it stands).

    :return: (x, y) in m, base_link, and the yaw in rad.
    """
    xy = rng.uniform(np.asarray(cfg.object.region_low), np.asarray(cfg.object.region_high))
    return (float(xy[0]), float(xy[1])), float(rng.uniform(-np.pi, np.pi))


def draw_object(rng: np.random.Generator, cfg: EnvConfig,
                oblong_difference: float = 0.0) -> Tuple[str, Tuple[float, ...], float]:
    """One object of ``object.variety``: its kind, nominal dimensions and mass.

    :param oblong_difference: m; an oblong box's top sides at least this far apart (the scenes of
        several objects, so that its kind is one a camera can tell: :mod:`fr5_rl.scenes`); 0: drawn
        independently, as the environment draws them.
    :return: the kind; (radius, height) of a cylinder or (half_x, half_y, half_z) of a box with
        ``half_x >= half_y`` (its longer top side along its own x), m; the mass, kg.
    """
    variety = cfg.object.variety
    kind = variety.kinds[int(rng.integers(len(variety.kinds)))]
    if kind == "cylinder":
        dims: Tuple[float, ...] = (float(rng.uniform(*variety.cylinder_radius)),
                                   float(rng.uniform(*variety.cylinder_height)))
    else:
        side = float(rng.uniform(*variety.box_side))
        if rng.uniform() < variety.box_square_share:
            other = side
        elif oblong_difference <= 0.0:
            other = float(rng.uniform(*variety.box_side))
        else:
            other = _other_side(rng, variety.box_side, side, oblong_difference)
        height = float(rng.uniform(*variety.box_height))
        dims = (max(side, other) / 2.0, min(side, other) / 2.0, height / 2.0)
    return kind, dims, float(rng.uniform(*variety.mass))


def _other_side(rng: np.random.Generator, box_side: Sequence[float], side: float, difference: float) -> float:
    """A box's second top side (m), uniform over ``box_side`` less the band within ``difference``
    of ``side`` (one draw, as the unconstrained side takes)."""
    low, high = float(box_side[0]), float(box_side[1])
    below, above = max(0.0, side - difference - low), max(0.0, high - side - difference)
    if below + above <= 0.0:
        raise ConfigError(f"object.variety.box_side {list(box_side)} is too narrow for oblong tops with sides "
                          f"{difference:g} m apart")
    pick = float(rng.uniform(0.0, below + above))
    return low + pick if pick < below else side + difference + (pick - below)


def draw_goal(rng: np.random.Generator, cfg: EnvConfig, object_xy: Sequence[float]) -> Tuple[float, float, float]:
    """Where the place task sets the object down: uniform over ``object.region_*``, at least
    ``place.min_goal_distance`` from the object (else, after ``place.goal_attempts`` draws, the
    farthest drawn), at a uniform yaw.

    :return: (x, y) in m, base_link, and the yaw in rad.
    """
    place, obj = cfg.place, cfg.object
    low, high = np.asarray(obj.region_low), np.asarray(obj.region_high)
    best, best_distance = None, -1.0
    for _ in range(place.goal_attempts):
        xy = rng.uniform(low, high)
        distance = float(np.hypot(xy[0] - object_xy[0], xy[1] - object_xy[1]))
        if distance > best_distance:
            best, best_distance = xy, distance
        if distance >= place.min_goal_distance:
            break
    return float(best[0]), float(best[1]), float(rng.uniform(-np.pi, np.pi))
