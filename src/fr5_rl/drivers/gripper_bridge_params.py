"""The gripper bridge's parameters (``config/gripper_bridge.yaml``), typed and checked."""
from __future__ import annotations

from dataclasses import dataclass
from urllib.parse import urlparse

from ..config import ConfigError

MODES = ("position", "binary")
#: ``MoveGripper`` argument counts: the 6-argument SDK form, or the newer 10-argument one.
MOVE_GRIPPER_FORMS = (6, 10)


@dataclass(frozen=True)
class GripperBridgeParams:
    """``config/gripper_bridge.yaml``: the gripper bridge node's ~private parameters.

    Widths are metres, times seconds unless the name says ms, percentages 0 … 100.
    """

    controller_url: str
    mode: str
    command_topic: str
    joint_states_topic: str
    fault_topic: str
    gripper_index: int
    move_gripper_args: int
    velocity_percent: int
    force_percent: int
    max_time_ms: int
    deadband_percent: int
    invert_percent: bool
    reset_settle: float
    activation_settle: float
    reactivate_after_reconnect: bool
    readback_rate: float
    zero_debounce: float
    readback_max_age: float
    readback_retry: float
    binary_threshold: float
    binary_hysteresis: float
    max_call_rate: float
    call_timeout: float
    retry_initial: float
    retry_max: float
    probe_period: float
    status_rate: float
    error_log_period: float
    startup_grace: float

    def check(self, source: str) -> None:
        """Refuse values the SDK or the bridge cannot work with.

        :param source: where the values came from, for the error message.
        :raises ConfigError: naming the first bad key.
        """
        if self.mode not in MODES:
            raise ConfigError(f"{source}: 'mode' must be position or binary, got {self.mode!r}")
        parsed = urlparse(self.controller_url)
        if parsed.scheme != "http" or not parsed.hostname:
            raise ConfigError(f"{source}: 'controller_url' must look like http://HOST:PORT, got {self.controller_url!r}")
        for name in ("velocity_percent", "force_percent"):
            if not 0 <= getattr(self, name) <= 100:
                raise ConfigError(f"{source}: '{name}' must be in 0 … 100, got {getattr(self, name)}")
        if not 0 <= self.max_time_ms <= 30000:
            raise ConfigError(f"{source}: 'max_time_ms' must be in 0 … 30000 (the SDK's range), got {self.max_time_ms}")
        if self.move_gripper_args not in MOVE_GRIPPER_FORMS:
            raise ConfigError(f"{source}: 'move_gripper_args' must be 6 or 10, got {self.move_gripper_args}")
        if not 1 <= self.deadband_percent <= 100:
            raise ConfigError(f"{source}: 'deadband_percent' must be in 1 … 100, got {self.deadband_percent}")
        for name in ("max_call_rate", "call_timeout", "retry_initial", "retry_max", "status_rate"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"{source}: '{name}' must be positive, got {getattr(self, name)}")
        if self.retry_max < self.retry_initial:
            raise ConfigError(f"{source}: 'retry_max' ({self.retry_max}) must be >= 'retry_initial' ({self.retry_initial})")
        for name in ("activation_settle", "reset_settle", "binary_hysteresis", "probe_period", "error_log_period",
                     "readback_rate", "zero_debounce", "readback_max_age", "readback_retry"):
            if getattr(self, name) < 0:
                raise ConfigError(f"{source}: '{name}' must be >= 0, got {getattr(self, name)}")
        if self.readback_max_age > 0 and not self.readback_retry > 0:
            raise ConfigError(f"{source}: 'readback_retry' must be positive while 'readback_max_age' is on "
                              f"({self.readback_max_age:g} s), got {self.readback_retry:g}: a read-back lost to the "
                              "controller's transient 0 would otherwise never be tried again before a move")


# ---------------------------------------------------------------------------------------------
# The bridge.
