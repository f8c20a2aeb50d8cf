"""~private parameters of a node, typed, with their defaults from config/<node>.yaml only."""
from __future__ import annotations

from typing import Any, Iterator, Mapping, Optional, Tuple, Type, TypeVar

import rospy

from ..config import ConfigError, deep_update, load_yaml, typed

T = TypeVar("T")


def node_parameters(cls: Type[T], config_name: str) -> T:
    """``config/<config_name>.yaml`` overridden by the node's ~private parameters, as ``cls``.

    A ~private parameter the file does not know (a typo in a launch file) is refused, as is a
    value of the wrong type; the error names the parameter. A section of the file (a mapping,
    e.g. ``detector:``) is a nested parameter: ``~detector/min_height`` overrides that one key,
    the others keep the file's values.
    """
    defaults = load_yaml(config_name)
    private = rospy.get_name().rstrip("/") + "/"
    given = sorted(name[len(private):] for name in rospy.get_param_names() if name.startswith(private))
    unknown = [name for name in given if name.split("/")[0] not in defaults]
    if unknown:
        raise ConfigError(f"unknown parameter ~{unknown[0]}; {rospy.get_name()} takes: {', '.join(defaults)} "
                          f"(defaults in config/{config_name}.yaml)")
    values = {key: _merged(value, rospy.get_param(f"~{key}", value)) for key, value in defaults.items()}
    return typed(cls, values, f"{rospy.get_name()} parameters (defaults: config/{config_name}.yaml)")


def _merged(default: Any, given: Any) -> Any:
    """A parameter's value: ``given`` as it is, or, for a section, merged key by key over the
    file's (a key the file lacks is kept, for ``typed`` to refuse by its full name)."""
    if isinstance(default, dict) and isinstance(given, Mapping):
        return deep_update(default, given, strict=False)
    return given


def _flat(values: Mapping[str, Any], prefix: str = "") -> Iterator[Tuple[str, Any]]:
    """``(name, value)`` of every parameter, a section's keys as ``section/key``."""
    for key, value in values.items():
        if isinstance(value, dict):
            yield from _flat(value, f"{prefix}{key}/")
        else:
            yield f"{prefix}{key}", value


def exit_if_help_asked(program: str, summary: str, config_name: str = "") -> None:
    """``rosrun fr5_rl <program> --help``: print the node's usage and its ~private parameters
    with their defaults (from ``config/<config_name>.yaml``), then exit 0 without a ROS master."""
    import sys

    if not any(arg in ("-h", "--help") for arg in sys.argv[1:]):
        return
    lines = [f"usage: rosrun fr5_rl {program} [_param:=value ...] [topic:=remapped ...]", "", summary.strip()]
    if config_name:
        lines += ["", f"~private parameters (defaults: config/{config_name}.yaml):"]
        lines += [f"  _{key}:={str(value).lower() if isinstance(value, bool) else value}"
                  for key, value in _flat(load_yaml(config_name))]
    print("\n".join(lines))
    sys.exit(0)


def described_arm(default: Optional[str] = None) -> Optional[str]:
    """The arm the running launch describes (``/robot_description``, which robot_description.py
    names after the arm), if it is one of the family's; else ``default`` (no description, or a
    vendor's URDF)."""
    from ..config import robot_names
    from .robot_description import robot_name

    if not rospy.has_param("/robot_description"):
        return default
    name = robot_name(rospy.get_param("/robot_description"))
    return name if name in robot_names() else default
