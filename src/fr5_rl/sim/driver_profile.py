"""A driver profile: how an arm's driver turns commands into motion, in one YAML file.

``config/sim_node_fairino.yaml`` is the shipped profile (the vendor's ros_control driver, as its
code says); ``fit_driver.py`` writes one fitted to a recorded run; a person may write one by
hand. The simulator node loads it as its ~private parameters (``sim_policy.launch
driver_profile:=FILE``) and training draws its timing from it (``train.py --driver-profile
FILE``), so both run the same model of the driver:

- ``servo_rate`` (Hz) and ``servo_delay_cycles``: the driver latches the newest command once per
  cycle and it acts ``servo_delay_cycles`` cycles later (:class:`~fr5_rl.sim.servo.ServoCycle`);
- ``response_time_constant_s`` (s, one per joint, controller order): the first-order lag with
  which each joint follows what the servo applies (:class:`~fr5_rl.sim.servo.FirstOrderResponse`);
- ``physics_dt`` (s) and ``publish_rate`` (Hz, joint states): the stand-in's own step and the
  driver's state rate.

Every other key of the file is a simulator-node parameter (topics, interfaces) and is kept as
it is.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Sequence

import yaml

from ..config import ConfigError, check_time_constants, load_yaml, whole_multiple

#: The keys a profile's driver model is read from (the rest are simulator-node parameters).
MODEL_KEYS = ("servo_rate", "servo_delay_cycles", "response_time_constant_s", "physics_dt", "publish_rate")


@dataclass(frozen=True)
class DriverProfile:
    """The driver model of a profile file, checked.

    :param servo_rate: Hz of the servo cycle; 0: a command acts from the next physics step.
    :param servo_delay_cycles: whole cycles between latching a command and its effect.
    :param response_time_constant_s: first-order lag per joint (s), controller order; empty or
        all 0: the joints follow the servo's targets at once.
    :param physics_dt: s, the simulator's physics step behind this driver.
    :param publish_rate: Hz, the driver's joint states.
    :param settings: the whole file (every key, as written), for the simulator node.
    :param source: where it was read from, for messages.
    """

    servo_rate: float
    servo_delay_cycles: int
    response_time_constant_s: List[float]
    physics_dt: float
    publish_rate: float
    settings: Dict[str, Any] = field(default_factory=dict)
    source: str = "<profile>"

    def check(self, n_joints: int = 6) -> None:
        """Refuse what no simulator can run.

        :raises ConfigError: negative or non-finite values, a servo period or state period that
            is not a whole number of physics steps, a time constant list of the wrong length.
        """
        where = self.source
        if not (math.isfinite(self.servo_rate) and self.servo_rate >= 0.0) or self.servo_delay_cycles < 0:
            raise ConfigError(f"{where}: servo_rate (Hz) and servo_delay_cycles must be >= 0 (0: no servo cycle)")
        if not (math.isfinite(self.physics_dt) and self.physics_dt > 0.0) or not self.publish_rate > 0.0:
            raise ConfigError(f"{where}: physics_dt (s) and publish_rate (Hz) must be > 0")
        if self.servo_rate > 0.0 and whole_multiple(1.0 / self.servo_rate, self.physics_dt) is None:
            raise ConfigError(f"{where}: 1 / servo_rate ({1.0 / self.servo_rate:g} s) must be a whole multiple of "
                              f"physics_dt ({self.physics_dt:g} s)")
        if whole_multiple(1.0 / self.publish_rate, self.physics_dt) is None:
            raise ConfigError(f"{where}: 1 / publish_rate ({1.0 / self.publish_rate:g} s) must be a whole multiple "
                              f"of physics_dt ({self.physics_dt:g} s)")
        check_time_constants(where, "response_time_constant_s", self.response_time_constant_s, n_joints)

    @property
    def servo_period(self) -> float:
        """s per servo cycle (0 without a cycle)."""
        return 1.0 / self.servo_rate if self.servo_rate > 0.0 else 0.0

    def command_delay_range(self) -> List[float]:
        """s a command waits before it acts, from its arrival: the wait for the next cycle
        (0 .. one cycle) and then ``servo_delay_cycles`` whole cycles; ``[0, 0]`` without a cycle."""
        period = self.servo_period
        return [self.servo_delay_cycles * period, (self.servo_delay_cycles + 1) * period]

    def env_randomisation(self) -> Dict[str, Any]:
        """The environment's ``randomisation`` keys that put this driver into training (merged
        over a hyperparameter file's by ``train.py --driver-profile``): the command delay its
        cycle gives, the age of a joint state at its rate, its physics step and its response."""
        return {
            "command_delay_s": self.command_delay_range(),
            "observation_age_s": [0.0, round(1.0 / self.publish_rate, 9)],
            "physics_dt_choices": [self.physics_dt],
            "response_time_constant_s": list(self.response_time_constant_s),
        }

    def with_model(self, servo_rate: float, servo_delay_cycles: int,
                   response_time_constant_s: Sequence[float], source: Optional[str] = None) -> "DriverProfile":
        """This profile with another driver model (the file's other keys kept)."""
        settings = dict(self.settings)
        settings.update(servo_rate=float(servo_rate), servo_delay_cycles=int(servo_delay_cycles),
                        response_time_constant_s=[float(t) for t in response_time_constant_s])
        profile = DriverProfile(float(servo_rate), int(servo_delay_cycles), [float(t) for t in response_time_constant_s],
                                self.physics_dt, self.publish_rate, settings, source or self.source)
        profile.check(len(response_time_constant_s) or 6)
        return profile


def load_driver_profile(path_or_name: str | Path,
                        layers: Sequence[str | Path] = ("sim_node", "sim_node_fairino")) -> DriverProfile:
    """Read a profile as the simulator node gets it in the rehearsal: ``layers`` (the node's
    defaults, then the driver's file, as ``sim_policy.launch driver:=fairino`` loads them), then
    ``path_or_name`` (a file, or a name in ``config/``) over them.

    :raises ConfigError: a file is missing, holds a key the simulator node does not take, or
        the model is invalid (:meth:`DriverProfile.check`).
    """
    defaults = load_yaml(layers[0])
    merged = dict(defaults)
    for layer in [*layers[1:], path_or_name]:
        given = load_yaml(layer)
        unknown = sorted(set(given) - set(defaults))
        if unknown:
            raise ConfigError(f"{layer}: unknown key {unknown[0]!r}; a driver profile holds simulator-node "
                              f"parameters ({', '.join(MODEL_KEYS)}, topics, ...; see config/{layers[0]}.yaml)")
        merged.update(given)
    settings = {key: value for key, value in merged.items() if key not in defaults or value != defaults[key]}
    try:
        profile = DriverProfile(float(merged["servo_rate"]), int(merged["servo_delay_cycles"]),
                                [float(t) for t in (merged.get("response_time_constant_s") or [])],
                                float(merged["physics_dt"]), float(merged["publish_rate"]), settings,
                                str(path_or_name))
    except (TypeError, ValueError) as error:
        raise ConfigError(f"{path_or_name}: {error}") from None
    profile.check()
    return profile


def write_driver_profile(profile: DriverProfile, path: Path, header: str, force: bool = False) -> None:
    """Write ``profile``'s keys (the model and every other key it was read with) as YAML,
    ``header`` as comments above them.

    :raises FileExistsError: ``path`` exists and ``force`` is False (nothing is written).
    """
    if path.exists() and not force:
        raise FileExistsError(f"{path} exists; pass --force to replace it")
    lines = [f"# {line}" if line else "#" for line in header.rstrip().splitlines()]
    body = yaml.safe_dump(profile_settings(profile), sort_keys=False, default_flow_style=None)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text("\n".join(lines) + "\n" + body, encoding="utf-8")
    tmp.replace(path)


def profile_settings(profile: DriverProfile) -> Dict[str, Any]:
    """The keys a profile file holds: its other settings, then its driver model."""
    settings: Dict[str, Any] = {key: value for key, value in profile.settings.items() if key not in MODEL_KEYS}
    settings.update(servo_rate=profile.servo_rate, servo_delay_cycles=profile.servo_delay_cycles,
                    response_time_constant_s=[round(t, 5) for t in profile.response_time_constant_s],
                    physics_dt=profile.physics_dt, publish_rate=profile.publish_rate)
    return settings


def profile_summary(profile: DriverProfile) -> Mapping[str, Any]:
    """The driver model as plain values (reports)."""
    return {"servo_rate": profile.servo_rate, "servo_delay_cycles": profile.servo_delay_cycles,
            "response_time_constant_s": list(profile.response_time_constant_s),
            "physics_dt": profile.physics_dt, "publish_rate": profile.publish_rate}
