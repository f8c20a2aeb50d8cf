"""The simulator node's settings, typed and without ROS: the node reads them as ~private
parameters over ``config/sim_node.yaml``; the chain emulation and the replay read the same
file (with a driver profile's file over it) through :func:`load_sim_node_params`."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, List, Mapping, Optional

from ..config import ConfigError, check_positive, check_time_constants, config_path, deep_update, load_yaml, typed
from ..env_config import TASK_NAMES
from .controller_emulator import ControllerEmulatorSettings


@dataclass(frozen=True)
class SimNodeParams:
    """``config/sim_node.yaml``: the simulator node's ~private parameters."""

    task: str
    model: str  # the policy's model directory: its task is judged and its arm simulated ("": none given)
    caller_dir: str  # where a relative model was typed (roslaunch's directory); "": the current one
    robot: str  # the arm, which must be the model's ("": the model's, else fr5)
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
    publish_velocities: bool
    truth_joint_states_topic: str
    command_topic: str
    gripper_interface: str
    gripper_command_topic: str
    controller_port: int
    controller_emulator: ControllerEmulatorSettings
    target_topic: str
    publish_target: bool
    target_shape_topic: str
    goal_topic: str
    goal_frame: str
    object_topic: str
    publish_finger_joints: bool
    servo_rate: float
    servo_delay_cycles: int
    response_time_constant_s: List[float]
    lockstep: bool
    lockstep_command_timeout: float
    lockstep_gripper: bool
    policy_reset_service: str
    policy_enable_service: str
    teleport_settle_time: float
    policy_call_timeout: float
    episode_start: str
    first_command_timeout: float
    outcome_log: str
    scene: str = ""  # "": one object an episode; "clear": a scene of several, cleared one object an episode
    scenes: int = 0  # scene "clear": stop after this many scenes (0: run on, or ~episodes)
    first_scene: int = 0  # scene "clear": start at this scene of the seed's (to replay one)
    neighbours_topic: str = ""  # scene "clear": the other objects, for the simulated camera (MarkerArray, base_link)
    cell_next_service: str = ""  # scene "clear": fr5_rl/NextObject (the detector's ~next): its answer is the next object judged

    def check(self, source: str) -> None:
        if self.scene not in ("", "clear"):
            raise ConfigError(f"{source}: 'scene' must be \"\" (one object) or clear, got {self.scene!r}")
        if self.scenes < 0 or self.first_scene < 0 or ((self.scenes or self.first_scene) and not self.scene):
            raise ConfigError(f"{source}: 'scenes' and 'first_scene' must be >= 0, and only count with scene: clear")
        if self.scene and self.lockstep:
            raise ConfigError(f"{source}: scene: clear runs in real time (its camera renders every object); "
                              "set ~lockstep false")
        if self.servo_rate < 0 or self.servo_delay_cycles < 0:
            raise ConfigError(f"{source}: servo_rate and servo_delay_cycles must be >= 0 (0: no servo cycle)")
        check_time_constants(source, "response_time_constant_s", self.response_time_constant_s)
        check_positive(source, lockstep_command_timeout=self.lockstep_command_timeout)
        if self.gripper_interface not in ("topic", "xmlrpc"):
            raise ConfigError(f"{source}: 'gripper_interface' must be topic or xmlrpc, got {self.gripper_interface!r}")
        if self.gripper_interface == "xmlrpc" and self.lockstep:
            raise ConfigError(f"{source}: 'gripper_interface: xmlrpc' runs in real time only (the XML-RPC path "
                              "is asynchronous); set ~lockstep false")
        if self.episode_start not in ("reset", "go_to_start"):
            raise ConfigError(f"{source}: 'episode_start' must be reset or go_to_start, got {self.episode_start!r}")
        if self.episode_start == "go_to_start" and (self.lockstep or not self.policy_reset_service):
            raise ConfigError(f"{source}: 'episode_start: go_to_start' needs real time and a policy_reset_service "
                              "(the policy node's start move begins each episode)")
        if self.task not in ("", *TASK_NAMES):
            raise ConfigError(f"{source}: 'task' must be one of {', '.join(TASK_NAMES)} or \"\" (the model's), "
                              f"got {self.task!r}")
        check_positive(source, publish_rate=self.publish_rate, physics_dt=self.physics_dt, camera_rate=self.camera_rate,
                  marker_rate=self.marker_rate, solver_iterations=self.solver_iterations)
        if min(self.episodes, self.camera_noise_std, self.pause_between_episodes, self.reset_settle_time,
               self.first_command_timeout, self.teleport_settle_time) < 0 or self.policy_call_timeout <= 0:
            raise ConfigError(f"{source}: episodes, camera_noise_std, pause_between_episodes, reset_settle_time, "
                              "first_command_timeout and teleport_settle_time must be >= 0, policy_call_timeout > 0")


def load_sim_node_params(profile: Optional[str] = None, overrides: Optional[Mapping[str, Any]] = None) -> SimNodeParams:
    """``config/sim_node.yaml``, with a driver profile's file over it (``fairino``:
    ``config/sim_node_fairino.yaml``, as ``sim_policy.launch driver:=fairino`` loads it) and
    ``overrides`` over both.

    :raises ConfigError: an unknown profile, or a key or value the node would refuse.
    """
    data = load_yaml("sim_node")
    if profile not in (None, "default"):
        if not config_path(f"sim_node_{profile}").is_file():
            raise ConfigError(f"no driver profile '{profile}': config/sim_node_{profile}.yaml does not exist")
        data = deep_update(data, load_yaml(f"sim_node_{profile}"))
    return typed(SimNodeParams, deep_update(data, overrides or {}), f"config/sim_node.yaml ({profile or 'default'})")
