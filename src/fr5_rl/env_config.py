"""``config/env.yaml`` typed: :class:`EnvConfig`, read once and passed down.

The environments, the simulator, the tasks and the deployment step all read these settings, so
the schema sits in the shared layer beside :mod:`fr5_rl.config`'s loaders rather than in any one
of them. Dataclasses rather than pydantic: the package's other files (node parameters,
hyperparameters) already load through :func:`fr5_rl.config.typed`, attribute reads are plain and
fast on the env's hot path, and no dependency is added. Every default lives in ``env.yaml``; the
classes here hold none, so a value is written once.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Union

from .gripper import BridgeTiming, load_bridge_timing
from .motion_guard import MotionGuardSettings
from .config import (DEFAULT_ROBOT, ConfigError, check_time_constants, deep_update, load_robot_spec, load_yaml,
                     robot_config, typed, whole_multiple)


@dataclass(frozen=True)
class SimulationConfig:
    """``simulation``: physics step, solver and the simulated position controller.

    :param control_dt: s, one env step = one 50 Hz command of the policy node.
    :param physics_dt: s per physics step; divides ``control_dt``.
    :param gravity: m/s^2 along base z.
    :param gripper_force: N the fingers squeeze with.
    :param object_spinning_friction: m, the object's torsional friction (PyBullet's
        ``spinningFriction``): what resists the object turning about the pads' axis in the grasp.
    :param fingers_coupled: the two fingers move as the gripper's linkage moves them, mirrored,
        so that a held object stays centred; false: each finger on its own.
    """

    control_dt: float
    physics_dt: float
    solver_iterations: int
    gravity: float
    arm_position_gain: float
    arm_velocity_gain: float
    finger_position_gain: float
    gripper_force: float
    object_spinning_friction: float
    fingers_coupled: bool


@dataclass(frozen=True)
class TableConfig:
    """``table`` (base_link, m): the robot stands on it at the origin."""

    top_height: float
    size: List[float]  # x y thickness
    center_xy: List[float]
    lateral_friction: float


@dataclass(frozen=True)
class ObjectVarietyConfig:
    """``object.variety``: objects of several kinds and sizes, drawn per episode (the production
    line's boxes at any yaw and cylinders). Off: the one object ``object`` describes.

    Ranges are [low, high], drawn uniformly. A box's top is square in ``box_square_share`` of the
    boxes (both sides drawn once), else rectangular (two sides drawn apart, the longer along the
    box's own x). Every width the fingers close across stays inside the gripper's stroke.
    """

    enabled: bool
    kinds: List[str]  # drawn uniformly: cylinder | box
    cylinder_radius: List[float]  # m
    cylinder_height: List[float]  # m
    box_side: List[float]  # m, each side of the top
    box_height: List[float]  # m
    box_square_share: float
    mass: List[float]  # kg, replaces object.mass (object_mass_scale still applies when perturbed)

    def check(self, source: str) -> None:
        if not self.kinds or any(kind not in ("cylinder", "box") for kind in self.kinds):
            raise ConfigError(f"{source}: 'object.variety.kinds' must list cylinder and/or box, got {self.kinds}")
        for key in ("cylinder_radius", "cylinder_height", "box_side", "box_height", "mass"):
            low_high = getattr(self, key)
            if len(low_high) != 2 or not 0.0 < low_high[0] <= low_high[1]:
                raise ConfigError(f"{source}: 'object.variety.{key}' must be [low, high] with 0 < low <= high, "
                                  f"got {low_high}")
        if not 0.0 <= self.box_square_share <= 1.0:
            raise ConfigError(f"{source}: 'object.variety.box_square_share' must be in [0, 1], "
                              f"got {self.box_square_share}")


@dataclass(frozen=True)
class ObjectConfig:
    """``object``: the cup (cylinder) or cube, and where it is placed (base_link x y, m)."""

    shape: str
    radius: float
    half_extent: float
    height: float
    mass: float  # kg
    lateral_friction: float
    region_low: List[float]
    region_high: List[float]
    # With the arm left where the last episode ended (a real arm between episodes), a draw that
    # puts the object closer than this (m) to the arm or gripper is drawn again: nobody sets an
    # object down inside the hand, and PyBullet would shoot it out through the table.
    placement_clearance: float
    placement_attempts: int
    variety: ObjectVarietyConfig

    def check(self, source: str) -> None:
        if self.shape not in ("cylinder", "box"):
            raise ConfigError(f"{source}: 'object.shape' must be cylinder or box, got {self.shape!r}")
        low, high = self.region_low, self.region_high
        if len(low) != 2 or len(high) != 2 or any(lo >= hi for lo, hi in zip(low, high)):
            raise ConfigError("object.region_low must be below object.region_high (x y, metres)")
        if self.placement_clearance < 0 or self.placement_attempts < 1:
            raise ConfigError(f"{source}: 'object.placement_clearance' must be >= 0 m and 'object.placement_attempts' "
                              f">= 1, got {self.placement_clearance}, {self.placement_attempts}")


@dataclass(frozen=True)
class ActionConfig:
    """``action``: what the arm's six action values mean, their scale, and the command low-pass.

    ``space: joint``: six joint increments, ``max_joint_step`` (rad) at 1. ``space: tcp``: a step
    of the tcp pointing straight down, its translation in base_link (``max_tcp_translation_step``
    m at 1) and its turn about the vertical (``max_tcp_rotation_step`` rad at 1), turned into joint
    increments by the arm's inverse kinematics (:class:`fr5_rl.control.JointCommandShaper`), then
    limited the same way. ``gripper: width``: the last value is the opening width (-1 closed, +1
    open); ``open_close``: open above 0, else closed.
    """

    max_joint_step: float
    smoothing_alpha: float
    space: str
    max_tcp_translation_step: float
    max_tcp_rotation_step: float
    gripper: str

    def check(self, source: str) -> None:
        if self.space not in ACTION_SPACES:
            raise ConfigError(f"{source}: 'action.space' must be one of {', '.join(ACTION_SPACES)}, got {self.space!r}")
        if self.gripper not in GRIPPER_COMMANDS:
            raise ConfigError(f"{source}: 'action.gripper' must be one of {', '.join(GRIPPER_COMMANDS)}, "
                              f"got {self.gripper!r}")
        for name in ("max_tcp_translation_step", "max_tcp_rotation_step"):
            value = getattr(self, name)
            if not 0.0 < value < math.inf:
                raise ConfigError(f"{source}: 'action.{name}' must be a positive number, got {value!r}")


ACTION_SPACES = ("joint", "tcp")
GRIPPER_COMMANDS = ("width", "open_close")


@dataclass(frozen=True)
class JointStepHintConfig:
    """``observation.joint_step_hint`` (:class:`fr5_rl.observation.JointStepHint`)."""

    cartesian_step: float  # m
    rotation_step: float  # rad
    damping: float  # m
    joint_step_scale: float  # rad read as 1

    def check(self, source: str) -> None:
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if not 0.0 < value < math.inf:
                raise ConfigError(f"observation.joint_step_hint.{field.name} must be a positive number, got {value!r}")


@dataclass(frozen=True)
class ObservationConfig:
    """``observation``: normalisation of the observation vector and its optional blocks."""

    tcp_position_low: List[float]  # m, base_link
    tcp_position_high: List[float]
    relative_position_scale: float  # m mapped to +-1
    lift_scale: float  # m mapped to +-1
    previous_actions: int
    joint_step_hint: Optional[JointStepHintConfig]
    joint_velocity_source: str  # measured (the simulator's) | positions (estimated, as behind the FAIRINO driver)
    object_features: bool  # the object's yaw relative to the gripper (by its symmetry) and its size
    object_size_scale: float  # m of an object's extent mapped to 1

    def check(self, source: str) -> None:
        if self.object_size_scale <= 0:
            raise ConfigError(f"observation.object_size_scale must be > 0 m, got {self.object_size_scale}")
        if self.joint_velocity_source not in ("measured", "positions"):
            raise ConfigError(f"observation.joint_velocity_source must be measured or positions, "
                              f"got {self.joint_velocity_source!r}")
        if not 0 <= self.previous_actions <= 4:
            raise ConfigError(f"observation.previous_actions must be a whole number from 0 to 4, "
                              f"got {self.previous_actions!r}")


@dataclass(frozen=True)
class WorkspaceConfig:
    """``workspace``: the box (base_link, m) the tcp must stay in."""

    low: List[float]
    high: List[float]


@dataclass(frozen=True)
class ReachConfig:
    """``reach``: episode length, success test and start noise of the reach task."""

    simulation: Dict[str, Any]  # overrides of ``simulation`` for this task
    max_steps: int
    success_distance: float  # m
    max_approach_angle_deg: float
    min_open_width: float  # m
    start_joint_noise: float  # rad


@dataclass(frozen=True)
class GraspConfig:
    """``grasp``: episode length, lift and hold of the grasp task."""

    simulation: Dict[str, Any]
    max_steps: int
    lift_height: float  # m
    hold_time: float  # s
    knocked_over_angle_deg: float
    start_joint_noise: float  # rad
    close_distance: float  # m, tcp to grasp point within which the shaping asks the gripper to close
    out_of_reach_margin: float  # m beyond the placement region where a pushed object is out of reach
    grasp_point_height: float = 0.0  # m above the object centre: where the shaping leads the tcp


@dataclass(frozen=True)
class PlaceConfig:
    """``place``: pick the object up and set it down at a goal pose on the table (issue #53).

    Success is every test at once: the object rests within ``position_tolerance`` of the goal (xy),
    a box's yaw within ``yaw_tolerance_deg`` of the goal's modulo its top's symmetry, upright
    within ``upright_tolerance_deg``, released (no finger touches it and the tcp is at least
    ``release_clearance`` above its top), and at rest (slower than ``rest_speed``).
    """

    simulation: Dict[str, Any]
    max_steps: int
    start_joint_noise: float  # rad
    close_distance: float  # m, tcp to object within which the shaping asks the gripper to close
    out_of_reach_margin: float  # m beyond the placement region where an object is out of reach
    knocked_over_angle_deg: float
    min_goal_distance: float  # m, goal to the object's start (xy), at least
    goal_attempts: int  # draws of a goal that far away before the farthest drawn is taken
    carry_height: float  # m: the shaping lifts the object this high while carrying it
    position_tolerance: float  # m
    yaw_tolerance_deg: float
    upright_tolerance_deg: float
    release_clearance: float  # m, tcp above the object's top
    rest_speed: float  # m/s


@dataclass(frozen=True)
class RewardWeights:
    """``reward.weights`` of the shaping terms."""

    approach: float
    orientation: float
    gripper: float
    lift: float
    carry: float  # place: object to goal (xy)
    yaw: float  # place: a box's yaw to the goal's
    release: float  # place: the tcp clear above the placed object


@dataclass(frozen=True)
class RewardConfig:
    """``reward``: dense (potential-based shaping) or sparse, bonus and penalties."""

    mode: str
    weights: RewardWeights
    distance_scale: float  # m
    orientation_scale: float  # rad
    potential_gain: float
    success_bonus: float
    collision_penalty: float
    failure_penalty: float
    action_penalty: float

    def check(self, source: str) -> None:
        if self.mode not in ("dense", "sparse"):
            raise ConfigError("reward.mode must be 'dense' or 'sparse'")


@dataclass(frozen=True)
class RandomisationConfig:
    """``randomisation``: what is drawn per episode (and the in-period timing, per step)."""

    enabled: bool
    object_size_scale: List[float]
    object_mass_scale: List[float]
    friction_scale: List[float]
    joint_damping: List[float]  # N*m*s/rad
    action_latency_steps: List[int]  # inclusive range of whole control steps
    observation_noise_std: float  # m / rad
    physics_dt_choices: List[float]  # s
    command_delay_s: List[float]
    observation_age_s: List[float]
    timing_share: float
    plain_episode_share: float
    gripper_bridge_share: float
    gripper_bridge_emulation: bool  # the bridge node's own code against the emulated controller, not BridgedGripper
    guard_share: float  # share of episodes whose commands the policy node's motion guard limits
    target_share: float
    target_action_latency_steps: Optional[List[int]]  # inclusive range in the target's episodes, None: action_latency_steps
    target_latency_s: List[float]
    target_rate_hz: float
    gripper_latency_steps: Optional[List[int]]  # inclusive range drawn apart from the arm's, None: the arm's
    target_hidden_radius: float  # m, tcp to object centre within which a frame shows it hidden; 0: never
    # The detector tracker's "in the hand" (config/detector.yaml tracker: grasp_radius,
    # grasp_width_margin), and how far the object must have risen off its rest (m).
    target_in_hand_radius: float
    target_in_hand_width_margin: float
    target_in_hand_lift: float
    target_in_hand_from_grasp: bool  # the held object as the tracker computes it (rigid from the grasp), not its truth
    response_time_constant_s: List[float]  # s per joint, [] none
    placement_focus_share: float  # share of episodes whose object is placed in the focus region instead
    placement_focus_low: List[float]  # (x, y) m, base_link
    placement_focus_high: List[float]

    def check(self, source: str) -> None:
        check_time_constants("randomisation", "response_time_constant_s", self.response_time_constant_s)
        if not 0.0 <= self.placement_focus_share <= 1.0:
            raise ConfigError(f"randomisation.placement_focus_share: {self.placement_focus_share} must be in [0, 1]")
        low, high = self.placement_focus_low, self.placement_focus_high
        if len(low) != 2 or len(high) != 2 or any(lo >= hi for lo, hi in zip(low, high)):
            raise ConfigError(f"randomisation.placement_focus_low {low} must be below placement_focus_high {high} "
                              "(x y, metres, base_link)")
        if not 0.0 <= self.target_share <= 1.0:
            raise ConfigError(f"randomisation.target_share: {self.target_share} must be in [0, 1]")
        low, high = self.target_latency_s
        if not 0.0 <= low <= high:
            raise ConfigError(f"randomisation.target_latency_s: {self.target_latency_s} must satisfy 0 <= low <= high (s)")
        if self.target_rate_hz <= 0.0:
            raise ConfigError(f"randomisation.target_rate_hz: {self.target_rate_hz} must be positive (Hz)")
        if min(self.target_in_hand_radius, self.target_in_hand_width_margin, self.target_in_hand_lift) < 0.0:
            raise ConfigError("randomisation.target_in_hand_radius, target_in_hand_width_margin and "
                              "target_in_hand_lift must be >= 0 m")
        if not 0.0 <= self.target_hidden_radius < float("inf"):
            raise ConfigError(f"randomisation.target_hidden_radius: {self.target_hidden_radius} must be a finite "
                              "distance >= 0 (m; 0: the camera always sees the object)")
        for key in ("action_latency_steps", "target_action_latency_steps", "gripper_latency_steps"):
            steps = getattr(self, key)
            if steps is not None and not (len(steps) == 2 and 0 <= steps[0] <= steps[1]):
                raise ConfigError(f"randomisation.{key}: {steps} must be [low, high] whole steps with 0 <= low <= high")
        if not 0.0 <= self.gripper_bridge_share <= 1.0:
            raise ConfigError(f"randomisation.gripper_bridge_share: {self.gripper_bridge_share} must be in [0, 1]")
        if not 0.0 <= self.guard_share <= 1.0:
            raise ConfigError(f"randomisation.guard_share: {self.guard_share} must be in [0, 1]")
        if not 0.0 <= self.plain_episode_share < 1.0:
            raise ConfigError(f"randomisation.plain_episode_share: {self.plain_episode_share} must be in [0, 1)")
        if not 0.0 <= self.timing_share <= 1.0:
            raise ConfigError(f"randomisation.timing_share: {self.timing_share} must be in [0, 1]")


@dataclass(frozen=True)
class LinkRadii:
    """``safety_zone.link_radii`` (m): capsule radius of each link."""

    upperarm: float
    forearm: float
    wrist1: float
    wrist2: float
    gripper: float


@dataclass(frozen=True)
class SafetyZoneConfig:
    """``safety_zone``: margins checked on every command before the policy node sends it (m)."""

    table_margin: float
    tcp_min_height: float
    self_margin: float
    link_radii: LinkRadii
    gripper_length: float


TaskConfig = Union[ReachConfig, GraspConfig, PlaceConfig]
# The tasks the configuration describes: each has a section of that name (config/env.yaml) and a
# module in fr5_rl.tasks.
TASK_NAMES = ("reach", "grasp", "place")


@dataclass(frozen=True)
class DeployedChainConfig:
    """What the environment models of the deployed chain's own settings: read from the nodes'
    files when the configuration is loaded (``config/policy_node.yaml``'s ``guard``,
    ``config/gripper_bridge.yaml``'s rates), so each is written once and lands in a model's
    ``meta.json`` with the rest.

    :param guard: the policy node's motion guard (``randomisation.guard_share``'s episodes).
    :param bridge: the gripper bridge's timing (``randomisation.gripper_bridge_share``'s episodes).
    """

    guard: MotionGuardSettings
    bridge: BridgeTiming


@dataclass(frozen=True)
class EnvConfig:
    """``config/env.yaml`` merged with overrides and checked: every section typed.

    Build it with :func:`load_env_config`; :meth:`to_dict` gives the plain form saved in a
    model's ``meta.json``.
    """

    robot: str  # config/robots/<robot>.yaml: the arm, and the cell sized to it
    simulation: SimulationConfig
    table: TableConfig
    object: ObjectConfig
    action: ActionConfig
    observation: ObservationConfig
    workspace: WorkspaceConfig
    reach: ReachConfig
    grasp: GraspConfig
    place: PlaceConfig
    reward: RewardConfig
    randomisation: RandomisationConfig
    safety_zone: SafetyZoneConfig
    deployed: DeployedChainConfig  # from the nodes' files, not env.yaml

    def task(self, name: str) -> TaskConfig:
        """The section of task ``name`` (:data:`TASK_NAMES`)."""
        if name not in TASK_NAMES:
            raise ConfigError(f"unknown task '{name}'; choose one of {', '.join(TASK_NAMES)}")
        return getattr(self, name)

    def simulation_for(self, task: str) -> SimulationConfig:
        """``simulation`` with the task's own overrides (``<task>.simulation``) applied."""
        overrides = self.task(task).simulation
        known = {field.name for field in dataclasses.fields(SimulationConfig)}
        unknown = sorted(set(overrides) - known)
        if unknown:
            raise ConfigError(f"{task}.simulation: unknown key '{unknown[0]}'; known: {sorted(known)}")
        return typed(SimulationConfig, {**dataclasses.asdict(self.simulation), **overrides}, f"{task}.simulation")

    def object_rest_z(self, size_scale: float = 1.0) -> float:
        """z (m, base_link) of the object's centre when it stands upright on the table.

        :param size_scale: the episode's object size factor (1.0 = nominal, as deployed).
        """
        obj = self.object
        half_height = obj.height / 2.0 if obj.shape == "cylinder" else obj.half_extent
        return self.table.top_height + half_height * size_scale

    def to_dict(self) -> Dict[str, Any]:
        """Plain JSON-able form (``meta.json`` ``env_config``)."""
        return dataclasses.asdict(self)

    def check(self, source: str) -> None:
        """Refuse settings that would break the real robot's limits or the simulation."""
        variety = self.object.variety
        if variety.enabled:
            widest = max(2.0 * variety.cylinder_radius[1] if "cylinder" in variety.kinds else 0.0,
                         variety.box_side[1] if "box" in variety.kinds else 0.0)
            stroke = load_robot_spec(self.robot).max_opening_width
            if widest >= stroke:
                raise ConfigError(f"object.variety: objects up to {widest * 1000:.0f} mm across, but the gripper opens "
                                  f"{stroke * 1000:.0f} mm: keep every width the fingers close across below the stroke")
        for task in ("base", *TASK_NAMES):
            sim = self.simulation if task == "base" else self.simulation_for(task)
            if whole_multiple(sim.control_dt, sim.physics_dt) is None:
                raise ConfigError(f"{task}: simulation.physics_dt ({sim.physics_dt}) must divide control_dt "
                                  f"({sim.control_dt}) evenly")
        control_dt = self.simulation.control_dt
        randomisation = self.randomisation
        for choice in randomisation.physics_dt_choices:
            if whole_multiple(control_dt, choice) is None:
                raise ConfigError(f"randomisation.physics_dt_choices: {choice} must divide control_dt ({control_dt})")
        for key in ("command_delay_s", "observation_age_s"):
            low, high = getattr(randomisation, key)
            if not 0.0 <= low <= high <= control_dt:
                raise ConfigError(f"randomisation.{key}: [{low}, {high}] must satisfy 0 <= low <= high <= "
                                  f"control_dt ({control_dt} s): it is a time inside one control period")
        max_step = self.action.max_joint_step
        allowed = min(load_robot_spec(self.robot).velocity_limits) * control_dt
        if not 0.0 < max_step <= allowed + 1e-12:
            raise ConfigError(
                f"action.max_joint_step = {max_step} rad per {control_dt} s step would exceed the "
                f"{self.robot}'s slowest rated joint speed; use at most {allowed:.4f} rad (velocity limit x control_dt)")
        if not 0.0 < self.action.smoothing_alpha <= 1.0:
            raise ConfigError("action.smoothing_alpha must be in (0, 1]")


def load_env_config(overrides: Optional[Mapping[str, Any]] = None, path: Union[str, Path] = "env") -> EnvConfig:
    """Read ``config/env.yaml`` (or ``path``), size its cell to the arm, merge ``overrides`` and
    check the result.

    The arm is ``overrides["robot"]`` or env.yaml's ``robot``; its file's ``cell`` (table, placement
    region, workspace, …, sized to its reach) replaces env.yaml's values before ``overrides`` do.

    :param overrides: a nested mapping of keys to replace (unknown keys are refused).
    :raises ConfigError: an unknown key, a missing key, a wrong type or a value out of range, or an
        unknown robot; the message names the key.
    """
    base = load_yaml(path)
    robot = (overrides or {}).get("robot", base.get("robot", DEFAULT_ROBOT))
    if not isinstance(robot, str):
        raise ConfigError(f"env configuration: 'robot' must be an arm's name, got {robot!r}")
    cell = robot_config(robot).get("cell", {})
    base["deployed"] = {"guard": load_yaml("policy_node")["guard"], "bridge": dataclasses.asdict(load_bridge_timing())}
    merged = deep_update(deep_update(base, cell), overrides)
    return typed(EnvConfig, merged, "env configuration")
