"""The policy node's settings, typed and without ROS: the node reads them as ~private parameters
over ``config/policy_node.yaml``; the chain emulation reads the same file through
:func:`load_policy_node_params`."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Optional

from ..config import ConfigError, check_positive, deep_update, load_yaml, typed
from ..motion_guard import MotionGuardSettings


@dataclass(frozen=True)
class PolicyNodeParams:
    """``config/policy_node.yaml``: the policy node's ~private parameters."""

    model_dir: str
    caller_dir: str  # where a relative model_dir was typed (roslaunch's directory); "": the current one
    robot: str  # "": the model's arm
    backend: str
    rate: float
    base_frame: str
    joint_state_timeout: float
    target_timeout: float
    stale_target_rise: float  # m above the last target the tcp rises to on a stale target; 0: hold in place
    stale_target_rise_speed: float  # m/s
    stale_target_let_go: float  # s the fingers open, the arm still, before rising from an object last seen standing
    future_stamp_tolerance: float
    target_workspace_margin: float
    joint_states_topic: str
    finger_joint_states_topic: str
    joint_velocity_source: str
    gripper_fault_topic: str
    target_topic: str
    target_shape_topic: str
    goal_topic: str
    command_topic: str
    gripper_command_topic: str
    command_gripper: bool
    dry_run: bool
    dry_run_topic: str
    enabled: bool
    sim_time_input_wait: float
    fresh_state_wait: float
    fresh_state_max_age: float
    startup_grace: float
    start_move_timeout: float
    motion_guard: bool
    guard: MotionGuardSettings

    def check(self, source: str) -> None:
        if self.joint_velocity_source not in ("driver", "positions"):
            raise ConfigError(f"{source}: 'joint_velocity_source' must be driver or positions, "
                              f"got {self.joint_velocity_source!r}")
        if self.startup_grace < 0:
            raise ConfigError(f"{source}: 'startup_grace' must be >= 0 s, got {self.startup_grace}")
        if self.sim_time_input_wait < 0:
            raise ConfigError(f"{source}: 'sim_time_input_wait' must be >= 0 s, got {self.sim_time_input_wait}")
        if not 0.0 <= self.fresh_state_wait < 1.0 / self.rate:
            raise ConfigError(f"{source}: 'fresh_state_wait' must be >= 0 s and shorter than a control period "
                              f"({1.0 / self.rate:g} s), got {self.fresh_state_wait}")
        if not 0.0 <= self.fresh_state_max_age < 1.0 / self.rate:
            raise ConfigError(f"{source}: 'fresh_state_max_age' must be >= 0 s and shorter than a control period "
                              f"({1.0 / self.rate:g} s), got {self.fresh_state_max_age}")
        if self.backend not in ("torch", "onnx"):
            raise ConfigError(f"{source}: 'backend' must be torch or onnx, got {self.backend!r}")
        if not 0.0 <= self.stale_target_rise <= 0.5:
            raise ConfigError(f"{source}: 'stale_target_rise' must be 0 (off) to 0.5 m, got {self.stale_target_rise}")
        check_positive(source, rate=self.rate, joint_state_timeout=self.joint_state_timeout,
                       target_timeout=self.target_timeout, start_move_timeout=self.start_move_timeout,
                       stale_target_rise_speed=self.stale_target_rise_speed)
        if self.stale_target_let_go < 0.0:
            raise ConfigError(f"{source}: 'stale_target_let_go' must be >= 0 s, got {self.stale_target_let_go}")


def load_policy_node_params(overrides: Optional[Mapping[str, Any]] = None) -> PolicyNodeParams:
    """``config/policy_node.yaml`` with ``overrides`` (nested: ``{"guard": {...}}``) over it.

    :raises ConfigError: a key or value the node would refuse.
    """
    return typed(PolicyNodeParams, deep_update(load_yaml("policy_node"), overrides or {}), "config/policy_node.yaml")
