"""Loading and validating the package's YAML configuration (``config/*.yaml``).

Everything tunable lives in ``config/``; code reads it through this module so training, the
environments and the ROS nodes see the same numbers.
"""
from __future__ import annotations

import copy
import dataclasses
import math
import os
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Type, TypeVar

import numpy as np
import yaml


class ConfigError(ValueError):
    """A configuration value is missing or inconsistent; the message says what to change."""


def package_root() -> Path:
    """Root of the fr5_rl package (the directory holding package.xml).

    Works from the source tree, the catkin devel space and an installed share directory:
    ``FR5_RL_ROOT`` overrides, otherwise the source layout ``<root>/src/fr5_rl`` is tried,
    then ``rospkg``.
    """
    env_root = os.environ.get("FR5_RL_ROOT")
    if env_root:
        return Path(env_root)
    here = Path(__file__).resolve().parent
    candidate = here.parent.parent
    if (candidate / "package.xml").is_file():
        return candidate
    try:
        import rospkg

        return Path(rospkg.RosPack().get_path("fr5_rl"))
    except Exception as exc:  # pragma: no cover - only outside any known layout
        raise ConfigError(
            "cannot locate the fr5_rl package root; set FR5_RL_ROOT to the directory "
            "containing package.xml"
        ) from exc


def config_path(name: str) -> Path:
    """Path of ``config/<name>`` (``.yaml`` added when missing)."""
    if not name.endswith((".yaml", ".yml")):
        name += ".yaml"
    return package_root() / "config" / name


def load_yaml(path_or_name: str | Path) -> Dict[str, Any]:
    """Load a YAML mapping from a path, or from ``config/<name>.yaml`` for a bare name."""
    path = Path(path_or_name)
    if not path.is_file():
        path = config_path(str(path_or_name))
    if not path.is_file():
        raise ConfigError(f"configuration file not found: {path}")
    with open(path, "r", encoding="utf-8") as stream:
        data = yaml.safe_load(stream) or {}
    if not isinstance(data, dict):
        raise ConfigError(f"{path} must hold a YAML mapping at top level")
    return data


def deep_update(base: Dict[str, Any], overrides: Optional[Mapping[str, Any]], strict: bool = True) -> Dict[str, Any]:
    """Return a copy of ``base`` with ``overrides`` merged in recursively.

    :param strict: refuse keys that ``base`` lacks, so a typo in an override is an error rather
        than a silently ignored setting; False adds them (a file built on another, whose own
        checks come after the merge).
    """
    merged = copy.deepcopy(base)
    for key, value in (overrides or {}).items():
        if strict and key not in merged:
            raise ConfigError(f"unknown configuration key '{key}'; known keys: {sorted(merged)}")
        if isinstance(merged.get(key), dict) and isinstance(value, Mapping):
            merged[key] = deep_update(merged[key], value, strict)
        else:
            merged[key] = copy.deepcopy(value)
    return merged


@dataclass(frozen=True)
class RobotSpec:
    """The FR5 + gripper numbers every component uses (from ``config/robot.yaml``).

    Arrays are in controller joint order (``j1`` … ``j6``); radians, rad/s, metres.
    """

    joint_names: tuple
    finger_joint_names: tuple
    joint_origins_xyz: np.ndarray  # (6, 3) m, joint origin in the parent link frame
    joint_origins_rpy: np.ndarray  # (6, 3) rad
    lower_limits: np.ndarray
    upper_limits: np.ndarray
    velocity_limits: np.ndarray
    effort_limits: np.ndarray
    home_joint_positions: np.ndarray
    finger_travel: float  # m per finger; opening width = 2 * travel at most
    finger_velocity: float  # m/s per finger
    finger_effort: float  # N
    tcp_offset: float  # m from the flange along flange z
    base_frame: str
    flange_frame: str
    tcp_frame: str

    @property
    def max_opening_width(self) -> float:
        """Largest distance between the finger pads (m)."""
        return 2.0 * self.finger_travel


def load_robot_spec(path: str | Path = "robot") -> RobotSpec:
    """Read ``config/robot.yaml`` into a :class:`RobotSpec`, checking array lengths."""
    data = load_yaml(path)
    arm, gripper = data["arm"], data["gripper"]
    names = tuple(arm["joint_names"])
    n = len(names)

    def vec(key: str, source: Mapping[str, Any] = arm) -> np.ndarray:
        values = np.asarray(source[key], dtype=np.float64)
        if values.shape != (n,):
            raise ConfigError(f"robot.yaml: '{key}' needs {n} values, got {values.shape}")
        return values

    spec = RobotSpec(
        joint_names=names,
        finger_joint_names=tuple(gripper["joint_names"]),
        joint_origins_xyz=np.array([o["xyz"] for o in arm["joint_origins"]], dtype=np.float64),
        joint_origins_rpy=np.array([o["rpy"] for o in arm["joint_origins"]], dtype=np.float64),
        lower_limits=vec("lower_limits"),
        upper_limits=vec("upper_limits"),
        velocity_limits=vec("velocity_limits"),
        effort_limits=vec("effort_limits"),
        home_joint_positions=vec("home_joint_positions", data),
        finger_travel=float(gripper["finger_travel"]),
        finger_velocity=float(gripper["finger_velocity"]),
        finger_effort=float(gripper["finger_effort"]),
        tcp_offset=float(gripper["tcp_offset"]),
        base_frame=str(gripper["base_frame"]),
        flange_frame=str(gripper["flange_frame"]),
        tcp_frame=str(gripper["tcp_frame"]),
    )
    if np.any(spec.lower_limits >= spec.upper_limits):
        raise ConfigError("robot.yaml: every lower limit must be below its upper limit")
    if np.any(spec.home_joint_positions < spec.lower_limits) or np.any(
        spec.home_joint_positions > spec.upper_limits
    ):
        raise ConfigError("robot.yaml: home_joint_positions lies outside the joint limits")
    return spec


def load_env_config(overrides: Optional[Mapping[str, Any]] = None, path: str | Path = "env") -> Dict[str, Any]:
    """Read ``config/env.yaml``, merge ``overrides`` and validate the result."""
    cfg = deep_update(load_yaml(path), overrides)
    validate_env_config(cfg, load_robot_spec())
    return cfg


def simulation_settings(cfg: Mapping[str, Any], task: str) -> Dict[str, Any]:
    """``simulation`` with the task's own overrides (``<task>.simulation``) applied."""
    merged = dict(cfg["simulation"])
    for key, value in (cfg.get(task, {}).get("simulation") or {}).items():
        if key not in merged:
            raise ConfigError(f"{task}.simulation: unknown key '{key}'; known: {sorted(merged)}")
        merged[key] = value
    return merged


def whole_multiple(period: float, step: float) -> Optional[int]:
    """``period / step`` when ``step`` > 0 divides ``period`` a whole number (>= 1) of times,
    else None: how many physics steps make one control period, servo cycle or publish period."""
    if step <= 0:
        return None
    ratio = period / step
    return int(round(ratio)) if ratio >= 1.0 - 1e-6 and abs(ratio - round(ratio)) <= 1e-6 else None


def validate_env_config(cfg: Mapping[str, Any], robot: RobotSpec) -> None:
    """Refuse settings that would break the real robot's limits or the simulation."""
    for task in ("base", "reach", "grasp"):
        sim = cfg["simulation"] if task == "base" else simulation_settings(cfg, task)
        control_dt, physics_dt = float(sim["control_dt"]), float(sim["physics_dt"])
        if whole_multiple(control_dt, physics_dt) is None:
            raise ConfigError(
                f"{task}: simulation.physics_dt ({physics_dt}) must divide control_dt ({control_dt}) evenly"
            )
    control_dt = float(cfg["simulation"]["control_dt"])
    randomisation = cfg.get("randomisation", {})
    for choice in randomisation.get("physics_dt_choices") or []:
        if whole_multiple(control_dt, float(choice)) is None:
            raise ConfigError(f"randomisation.physics_dt_choices: {choice} must divide control_dt ({control_dt})")
    for key in ("command_delay_s", "observation_age_s"):
        low, high = (float(value) for value in randomisation.get(key, (0.0, 0.0)))
        if not 0.0 <= low <= high <= control_dt:
            raise ConfigError(f"randomisation.{key}: [{low}, {high}] must satisfy 0 <= low <= high <= control_dt "
                              f"({control_dt} s): it is a time inside one control period")
    share = float(randomisation.get("plain_episode_share", 0.0))
    if not 0.0 <= share < 1.0:
        raise ConfigError(f"randomisation.plain_episode_share: {share} must be in [0, 1)")
    timing_share = float(randomisation.get("timing_share", 1.0))
    if not 0.0 <= timing_share <= 1.0:
        raise ConfigError(f"randomisation.timing_share: {timing_share} must be in [0, 1]")
    max_step = float(cfg["action"]["max_joint_step"])
    allowed = float(np.min(robot.velocity_limits)) * control_dt
    if not 0.0 < max_step <= allowed + 1e-12:
        raise ConfigError(
            f"action.max_joint_step = {max_step} rad per {control_dt} s step would exceed the "
            f"FR5 velocity limit; use at most {allowed:.4f} rad (velocity limit x control_dt)"
        )
    alpha = float(cfg["action"]["smoothing_alpha"])
    if not 0.0 < alpha <= 1.0:
        raise ConfigError("action.smoothing_alpha must be in (0, 1]")
    previous = cfg["observation"].get("previous_actions", 0)
    if isinstance(previous, bool) or not isinstance(previous, int) or not 0 <= previous <= 4:
        raise ConfigError(f"observation.previous_actions must be a whole number from 0 to 4, got {previous!r}")
    hint = cfg["observation"].get("joint_step_hint")
    if hint is not None:
        keys = ("cartesian_step", "rotation_step", "damping", "joint_step_scale")
        if not isinstance(hint, Mapping) or set(hint) != set(keys):
            raise ConfigError(f"observation.joint_step_hint must be null or a mapping of {', '.join(keys)}, got {hint!r}")
        for key in keys:
            value = hint[key]
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 < float(value) < math.inf:
                raise ConfigError(f"observation.joint_step_hint.{key} must be a positive number, got {value!r}")
    if cfg["reward"]["mode"] not in ("dense", "sparse"):
        raise ConfigError("reward.mode must be 'dense' or 'sparse'")
    low, high = np.asarray(cfg["object"]["region_low"]), np.asarray(cfg["object"]["region_high"])
    if low.shape != (2,) or high.shape != (2,) or np.any(low >= high):
        raise ConfigError("object.region_low must be below object.region_high (x y, metres)")


def object_rest_z(cfg: Mapping[str, Any], size_scale: float = 1.0) -> float:
    """z (m, base_link) of the object's centre when it stands upright on the table.

    :param cfg: the environment configuration (``config/env.yaml`` merged with overrides).
    :param size_scale: the episode's object size factor (1.0 = nominal, as deployed).
    """
    obj = cfg["object"]
    half_height = float(obj["height"]) / 2.0 if obj["shape"] == "cylinder" else float(obj["half_extent"])
    return float(cfg["table"]["top_height"]) + half_height * size_scale


# ---------------------------------------------------------------------------------------------
# Typed loaders: one dataclass per kind of file. Defaults live in the YAML files only; the
# loaders refuse unknown keys, missing keys and wrong types, naming the key's path.

T = TypeVar("T")


def _join(path: str, key: str) -> str:
    return f"{path}.{key}" if path else str(key)


def _coerce(kind: Any, value: Any, source: str, path: str) -> Any:
    """``value`` checked against the annotation ``kind`` (bool, int, float, str, List, Dict,
    Optional, Any or a dataclass)."""
    origin, args = typing.get_origin(kind), typing.get_args(kind)

    def wrong(expected: str) -> ConfigError:
        return ConfigError(f"{source}: '{path}' must be {expected}, got {value!r}")

    if kind is Any:
        return value
    if origin is typing.Union:  # Optional[X]
        if value is None and type(None) in args:
            return None
        (inner,) = [arg for arg in args if arg is not type(None)]
        return _coerce(inner, value, source, path)
    if dataclasses.is_dataclass(kind):
        return typed(kind, value, source, path)
    if kind is bool:
        if not isinstance(value, bool):
            raise wrong("true or false")
        return value
    if kind is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise wrong("an integer")
        return value
    if kind is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise wrong("a number")
        return float(value)
    if kind is str:
        if not isinstance(value, str):
            raise wrong("a string")
        return value
    if origin in (list, List):
        if not isinstance(value, (list, tuple)):
            raise wrong("a list")
        return [_coerce(args[0] if args else Any, item, source, f"{path}[{index}]")
                for index, item in enumerate(value)]
    if origin in (dict, Dict):
        if not isinstance(value, Mapping):
            raise wrong("a mapping")
        return {key: _coerce(args[1] if args else Any, item, source, _join(path, key)) for key, item in value.items()}
    raise TypeError(f"unsupported annotation {kind!r} at {path}")  # pragma: no cover - a bug in a schema


def typed(cls: Type[T], data: Any, source: str, path: str = "") -> T:
    """Build the dataclass ``cls`` from a mapping, refusing unknown or missing keys and wrong
    types; the message names ``source`` and the key's dotted path. A ``check(source)`` method of
    the dataclass then validates values."""
    if not isinstance(data, Mapping):
        raise ConfigError(f"{source}: '{path or '(top level)'}' must be a mapping, got {data!r}")
    hints = typing.get_type_hints(cls)
    names = [field.name for field in dataclasses.fields(cls)]
    unknown = [key for key in data if key not in names]
    if unknown:
        raise ConfigError(f"{source}: unknown key '{_join(path, unknown[0])}'; known keys"
                          f"{' under ' + repr(path) if path else ''}: {', '.join(names)}")
    optional = {field.name for field in dataclasses.fields(cls)
                if field.default is not dataclasses.MISSING or field.default_factory is not dataclasses.MISSING}
    missing = [name for name in names if name not in data and name not in optional]
    if missing:
        raise ConfigError(f"{source}: missing key '{_join(path, missing[0])}'")
    instance = cls(**{name: _coerce(hints[name], data[name], source, _join(path, name))
                      for name in names if name in data})
    check = getattr(instance, "check", None)
    if check is not None:
        check(source)
    return instance


def load_typed(cls: Type[T], path_or_name: str | Path) -> T:
    """``typed(cls, ...)`` of a YAML file (a path, or a name in ``config/``)."""
    path = Path(path_or_name)
    source = str(path if path.is_file() else config_path(str(path_or_name)).relative_to(package_root()))
    return typed(cls, load_yaml(path_or_name), source)


def _positive(source: str, **values: float) -> None:
    for name, value in values.items():
        if not value > 0:
            raise ConfigError(f"{source}: '{name}' must be positive, got {value}")


@dataclass(frozen=True)
class PolicyNodeParams:
    """``config/policy_node.yaml``: the policy node's ~private parameters."""

    model_dir: str
    backend: str
    rate: float
    base_frame: str
    joint_state_timeout: float
    target_timeout: float
    future_stamp_tolerance: float
    target_workspace_margin: float
    joint_states_topic: str
    target_topic: str
    command_topic: str
    gripper_command_topic: str
    command_gripper: bool
    enabled: bool
    sim_time_input_wait: float

    def check(self, source: str) -> None:
        if self.sim_time_input_wait < 0:
            raise ConfigError(f"{source}: 'sim_time_input_wait' must be >= 0 s, got {self.sim_time_input_wait}")
        if self.backend not in ("torch", "onnx"):
            raise ConfigError(f"{source}: 'backend' must be torch or onnx, got {self.backend!r}")
        _positive(source, rate=self.rate, joint_state_timeout=self.joint_state_timeout,
                  target_timeout=self.target_timeout)


@dataclass(frozen=True)
class SimNodeParams:
    """``config/sim_node.yaml``: the simulator node's ~private parameters."""

    task: str
    seed: int
    episodes: int
    publish_rate: float
    physics_dt: float
    solver_iterations: int
    camera_rate: float
    camera_frame: str
    camera_noise_std: float
    marker_rate: float
    pause_between_episodes: float
    reset_settle_time: float
    joint_states_topic: str
    command_topic: str
    gripper_command_topic: str
    target_topic: str
    publish_target: bool
    object_topic: str
    publish_finger_joints: bool
    servo_rate: float
    servo_delay_cycles: int
    lockstep: bool
    lockstep_command_timeout: float
    lockstep_gripper: bool
    policy_reset_service: str
    outcome_log: str

    def check(self, source: str) -> None:
        if self.servo_rate < 0 or self.servo_delay_cycles < 0:
            raise ConfigError(f"{source}: servo_rate and servo_delay_cycles must be >= 0 (0: no servo cycle)")
        _positive(source, lockstep_command_timeout=self.lockstep_command_timeout)
        if self.task not in ("reach", "grasp"):
            raise ConfigError(f"{source}: 'task' must be reach or grasp, got {self.task!r}")
        _positive(source, publish_rate=self.publish_rate, physics_dt=self.physics_dt, camera_rate=self.camera_rate,
                  marker_rate=self.marker_rate, solver_iterations=self.solver_iterations)
        if min(self.episodes, self.camera_noise_std, self.pause_between_episodes, self.reset_settle_time) < 0:
            raise ConfigError(f"{source}: episodes, camera_noise_std, pause_between_episodes and reset_settle_time "
                              "must be >= 0")


@dataclass(frozen=True)
class StaticTransform:
    """One fixed frame: ``child`` in ``parent``, xyz (m) and URDF roll-pitch-yaw (rad)."""

    parent: str
    child: str
    xyz: List[float]
    rpy: List[float]


@dataclass(frozen=True)
class StaticTransforms:
    """``config/static_transforms.yaml``: every transform published on /tf_static."""

    transforms: List[StaticTransform]

    def check(self, source: str) -> None:
        for index, item in enumerate(self.transforms):
            if len(item.xyz) != 3 or len(item.rpy) != 3 or not np.all(np.isfinite(item.xyz + item.rpy)):
                raise ConfigError(f"{source}: 'transforms[{index}]' ({item.parent} -> {item.child}): "
                                  "xyz and rpy need 3 finite values each")
        children = [item.child for item in self.transforms]
        if len(set(children)) != len(children):
            raise ConfigError(f"{source}: a child frame appears twice (tf allows one parent per frame)")


@dataclass(frozen=True)
class NormalizeSettings:
    """VecNormalize settings of a hyperparameter file."""

    norm_obs: bool
    norm_reward: bool
    clip_obs: float


@dataclass(frozen=True)
class CriticWarmupSettings:
    """``critic_warmup`` of a hyperparameter file: for the first ``steps`` environment steps only
    the value function trains (the actor held), at ``learning_rate``, so that the first policy
    updates follow advantages of a critic that fits the actor's returns, not noise."""

    steps: int
    learning_rate: float

    def check(self, source: str) -> None:
        _positive(source, **{"critic_warmup.steps": self.steps, "critic_warmup.learning_rate": self.learning_rate})


@dataclass(frozen=True)
class ExpertStartSettings:
    """``expert_start`` of a hyperparameter file: a reverse curriculum
    (:mod:`fr5_rl.training.curriculum`). Each training episode starts after the scripted expert
    has run ``k`` steps from the reset, the policy taking over there: ``k`` is drawn from the
    last ``reach_back`` of ``max_steps``, first ``first_reach_back``; a share
    ``frontier_share`` of the starts is drawn from the frontier, the starts new since the last
    step back (:class:`fr5_rl.training.curriculum.ExpertStartCurriculum`). The reach-back grows by
    ``step_back`` whenever the last ``window`` training episodes begun at the frontier
    succeeded at a rate of ``promote_at`` or more, up to 1, then once more to plain resets.
    Evaluation always starts from plain resets."""

    max_steps: int
    first_reach_back: float
    promote_at: float
    window: int
    step_back: float
    frontier_share: float

    def check(self, source: str) -> None:
        _positive(source, **{"expert_start.max_steps": self.max_steps, "expert_start.window": self.window})
        for name, value in (("first_reach_back", self.first_reach_back), ("promote_at", self.promote_at),
                            ("step_back", self.step_back)):
            if not 0.0 < value <= 1.0:
                raise ConfigError(f"{source}: 'expert_start.{name}' must be in (0, 1], got {value!r}")
        if not 0.0 <= self.frontier_share <= 1.0:
            raise ConfigError(f"{source}: 'expert_start.frontier_share' must be in [0, 1], got {self.frontier_share!r}")


@dataclass(frozen=True)
class Hyperparameters:
    """``config/<algo>_<task>.yaml`` (rl-zoo style): everything a training run is made of.

    ``env`` is merged over ``config/env.yaml`` (its keys are checked there); ``algo_kwargs`` go
    to the Stable-Baselines3 constructor (their names are checked against it by training).
    """

    n_timesteps: int
    n_envs: int
    normalize: NormalizeSettings
    env: Dict[str, Any]
    algo_kwargs: Dict[str, Any]
    # Fine-tuning (train.py --init-from) a model whose critic never learnt (e.g. DAgger's).
    critic_warmup: Optional[CriticWarmupSettings] = None
    # Training episodes start part-way along the scripted expert's trajectories (a reverse curriculum).
    expert_start: Optional[ExpertStartSettings] = None

    def check(self, source: str) -> None:
        _positive(source, n_timesteps=self.n_timesteps, n_envs=self.n_envs)
        try:
            load_env_config(self.env)
        except ConfigError as error:
            raise ConfigError(f"{source}: 'env': {error}") from None

    def to_dict(self) -> Dict[str, Any]:
        """Plain JSON-able form (saved in a run's config.json; ``typed`` reads it back)."""
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class DaggerSettings:
    """The ``dagger`` section of ``config/dagger_<task>.yaml``."""

    rounds: int
    episodes: int
    epochs: int
    learning_rate: float
    expert_share_decay: float

    def check(self, source: str) -> None:
        _positive(source, rounds=self.rounds, episodes=self.episodes, epochs=self.epochs,
                  learning_rate=self.learning_rate)
        if not 0.0 <= self.expert_share_decay <= 1.0:
            raise ConfigError(f"{source}: 'dagger.expert_share_decay' must be in [0, 1]")


@dataclass(frozen=True)
class DaggerConfig:
    """``config/dagger_<task>.yaml``: DAgger rounds, the env variant, the network that holds it."""

    dagger: DaggerSettings
    env: Dict[str, Any]
    algo_kwargs: Dict[str, Any]

    def check(self, source: str) -> None:
        try:
            load_env_config(self.env)
        except ConfigError as error:
            raise ConfigError(f"{source}: 'env': {error}") from None
