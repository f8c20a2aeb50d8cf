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
from typing import Any, Dict, List, Mapping, Optional, Sequence, Type, TypeVar

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


# libyaml's parser where PyYAML was built with it: the same constructors (the same values, which
# a test checks for every shipped file), a tenth of the time. Every environment reads env.yaml
# and robots/<arm>.yaml: with the pure-Python parser a reach environment took 21-29 ms to build, with
# libyaml's 10.8 ms, and a 32-environment run builds 21 before its first step.
_YAML_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


def load_yaml(path_or_name: str | Path) -> Dict[str, Any]:
    """Load a YAML mapping from a path, or from ``config/<name>.yaml`` for a bare name."""
    path = Path(path_or_name)
    if not path.is_file():
        path = config_path(str(path_or_name))
    if not path.is_file():
        raise ConfigError(f"configuration file not found: {path}")
    with open(path, "r", encoding="utf-8") as stream:
        data = yaml.load(stream, Loader=_YAML_LOADER) or {}  # a safe loader, C or Python
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


DEFAULT_ROBOT = "fr5"


def robot_names() -> List[str]:
    """The arms this package describes: one ``config/robots/<name>.yaml`` each."""
    return sorted(path.stem for path in (package_root() / "config" / "robots").glob("*.yaml"))


def check_robot_name(robot: str) -> str:
    """``robot`` if ``config/robots/<robot>.yaml`` exists, else a :class:`ConfigError` naming the known arms."""
    names = robot_names()
    if robot not in names:
        raise ConfigError(f"unknown robot '{robot}': this fr5_rl describes {', '.join(names)} (config/robots/)")
    return robot


def urdf_path(robot: str) -> Path:
    """``urdf/<robot>.urdf`` in the package: the arm's generated description (``make meshes``)."""
    return package_root() / "urdf" / f"{check_robot_name(robot)}.urdf"


def dh_joint_origins(dh: Mapping[str, float]) -> List[Dict[str, List[float]]]:
    """The six URDF joint origins of a FAIRINO arm from its standard DH lengths (m).

    The family's chain (alpha = pi/2, 0, 0, pi/2, -pi/2, 0; a = 0, a2, a3, 0, 0, 0; d = d1, 0, 0,
    d4, d5, d6), laid out as the vendor's v6 URDFs lay it: every joint turns about its local z, and
    the URDF's zero pose is the DH zero pose. The flange face lies a further ``d6`` along the j6 axis.
    """
    half_pi = math.pi / 2.0
    return [
        {"xyz": [0.0, 0.0, 0.0], "rpy": [0.0, 0.0, 0.0]},
        {"xyz": [0.0, 0.0, float(dh["d1"])], "rpy": [half_pi, 0.0, 0.0]},
        {"xyz": [float(dh["a2"]), 0.0, 0.0], "rpy": [0.0, 0.0, 0.0]},
        {"xyz": [float(dh["a3"]), 0.0, 0.0], "rpy": [0.0, 0.0, 0.0]},
        {"xyz": [0.0, 0.0, float(dh["d4"])], "rpy": [half_pi, 0.0, 0.0]},
        {"xyz": [0.0, 0.0, float(dh["d5"])], "rpy": [-half_pi, 0.0, 0.0]},
    ]


def robot_config(robot: str = DEFAULT_ROBOT) -> Dict[str, Any]:
    """The description of arm ``robot`` with its gripper, as plain data: ``config/robots/<robot>.yaml``
    with ``config/gripper.yaml`` under ``gripper``. A model's ``meta.json`` keeps this as
    ``robot_config``; the loader compares it with the current files.
    """
    data = load_yaml(config_path(f"robots/{check_robot_name(robot)}"))
    if data.get("model") != robot:
        raise ConfigError(f"config/robots/{robot}.yaml: 'model' must be '{robot}', got {data.get('model')!r}")
    data["gripper"] = load_yaml("gripper")
    return data


@dataclass(frozen=True)
class RobotSpec:
    """The numbers of one FAIRINO arm + gripper that every component uses
    (``config/robots/<model>.yaml`` and ``config/gripper.yaml``).

    Arrays are in controller joint order (``j1`` … ``j6``); radians, rad/s, metres.
    """

    model: str  # config/robots/<model>.yaml
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
    flange_offset: float  # m from the last joint's frame (wrist3_Link) to flange_frame along its z
    tcp_offset: float  # m from flange_frame to the tcp along flange z
    base_frame: str
    flange_frame: str
    tcp_frame: str
    driver_flange_link: str  # the vendor driver's URDF link at our flange_frame (arm_tf:=driver)

    @property
    def max_opening_width(self) -> float:
        """Largest distance between the finger pads (m)."""
        return 2.0 * self.finger_travel

    @property
    def tcp_offset_from_wrist(self) -> float:
        """m from the last joint's frame (the wrist centre) to the tcp along its z."""
        return self.flange_offset + self.tcp_offset

    @property
    def arm_span(self) -> float:
        """m of upper arm and forearm (|a2| + |a3| of the DH table): what each arm's cell is sized by."""
        return float(abs(self.joint_origins_xyz[2][0]) + abs(self.joint_origins_xyz[3][0]))


def load_robot_spec(robot: str = DEFAULT_ROBOT) -> RobotSpec:
    """Read ``config/robots/<robot>.yaml`` (and the gripper) into a :class:`RobotSpec`, checking
    array lengths and limits.

    :param robot: the arm's model name (``fr5``, ``fr10``, …; :func:`robot_names`).
    """
    data = robot_config(robot)
    gripper = data["gripper"]
    source = f"config/robots/{robot}.yaml"
    names = tuple(data["joint_names"])
    n = len(names)

    def vec(key: str) -> np.ndarray:
        values = np.asarray(data[key], dtype=np.float64)
        if values.shape != (n,):
            raise ConfigError(f"{source}: '{key}' needs {n} values, got {values.shape}")
        return values

    origins = dh_joint_origins(data["dh"])
    spec = RobotSpec(
        model=robot,
        joint_names=names,
        finger_joint_names=tuple(gripper["joint_names"]),
        joint_origins_xyz=np.array([o["xyz"] for o in origins], dtype=np.float64),
        joint_origins_rpy=np.array([o["rpy"] for o in origins], dtype=np.float64),
        lower_limits=vec("lower_limits"),
        upper_limits=vec("upper_limits"),
        velocity_limits=vec("velocity_limits"),
        effort_limits=vec("effort_limits"),
        home_joint_positions=vec("home_joint_positions"),
        finger_travel=float(gripper["finger_travel"]),
        finger_velocity=float(gripper["finger_velocity"]),
        finger_effort=float(gripper["finger_effort"]),
        flange_offset=float(data["dh"]["d6"]),
        tcp_offset=float(data["gripper_mount_offset"]) + float(gripper["tcp_offset"]),
        base_frame=str(gripper["base_frame"]),
        flange_frame=str(data["flange_frame"]),
        tcp_frame=str(gripper["tcp_frame"]),
        driver_flange_link=str(data["driver_flange_link"]),
    )
    if np.any(spec.lower_limits >= spec.upper_limits):
        raise ConfigError(f"{source}: every lower limit must be below its upper limit")
    if np.any(spec.home_joint_positions < spec.lower_limits) or np.any(
        spec.home_joint_positions > spec.upper_limits
    ):
        raise ConfigError(f"{source}: home_joint_positions lies outside the joint limits")
    return spec


def whole_multiple(period: float, step: float) -> Optional[int]:
    """``period / step`` when ``step`` > 0 divides ``period`` a whole number (>= 1) of times,
    else None: how many physics steps make one control period, servo cycle or publish period."""
    if step <= 0:
        return None
    ratio = period / step
    return int(round(ratio)) if ratio >= 1.0 - 1e-6 and abs(ratio - round(ratio)) <= 1e-6 else None


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


def check_positive(source: str, **values: float) -> None:
    """Refuse any of ``values`` that is not above 0, naming it and ``source``."""
    for name, value in values.items():
        if not value > 0:
            raise ConfigError(f"{source}: '{name}' must be positive, got {value}")


def check_time_constants(source: str, name: str, values: Sequence[float], count: int = 6) -> None:
    """Refuse a per-joint list of time constants (s) that is neither empty (none) nor ``count``
    finite values >= 0, naming it and ``source``: a driver's response
    (``response_time_constant_s``), wherever a profile, the simulator node or the environment
    reads one."""
    if values and (len(values) != count or not all(math.isfinite(v) and v >= 0.0 for v in values)):
        raise ConfigError(f"{source}: '{name}' must be [] or {count} values >= 0 s (one per joint, j1..j{count}), "
                          f"got {list(values)}")
