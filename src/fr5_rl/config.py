"""Loading and validating the package's YAML configuration (``config/*.yaml``).

Everything tunable lives in ``config/``; code reads it through this module so training, the
environments and the ROS nodes see the same numbers.
"""
from __future__ import annotations

import copy
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, Mapping, Optional

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


def deep_update(base: Dict[str, Any], overrides: Optional[Mapping[str, Any]]) -> Dict[str, Any]:
    """Return a copy of ``base`` with ``overrides`` merged in recursively.

    Unknown top-level or nested keys are refused, so a typo in an override is an error rather
    than a silently ignored setting.
    """
    merged = copy.deepcopy(base)
    for key, value in (overrides or {}).items():
        if key not in merged:
            raise ConfigError(f"unknown configuration key '{key}'; known keys: {sorted(merged)}")
        if isinstance(merged[key], dict) and isinstance(value, Mapping):
            merged[key] = deep_update(merged[key], value)
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


def validate_env_config(cfg: Mapping[str, Any], robot: RobotSpec) -> None:
    """Refuse settings that would break the real robot's limits or the simulation."""
    for task in ("base", "reach", "grasp"):
        sim = cfg["simulation"] if task == "base" else simulation_settings(cfg, task)
        control_dt, physics_dt = float(sim["control_dt"]), float(sim["physics_dt"])
        substeps = control_dt / physics_dt if physics_dt > 0 else 0.0
        if physics_dt <= 0 or abs(substeps - round(substeps)) > 1e-6 or round(substeps) < 1:
            raise ConfigError(
                f"{task}: simulation.physics_dt ({physics_dt}) must divide control_dt ({control_dt}) evenly"
            )
    control_dt = float(cfg["simulation"]["control_dt"])
    for choice in cfg.get("randomisation", {}).get("physics_dt_choices") or []:
        ratio = control_dt / float(choice)
        if float(choice) <= 0 or abs(ratio - round(ratio)) > 1e-6:
            raise ConfigError(f"randomisation.physics_dt_choices: {choice} must divide control_dt ({control_dt})")
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
