"""Gymnasium environments FR5Reach-v0 and FR5Grasp-v0: a world, a robot and a task composed.

One ``step`` is one 50 Hz control period: the action goes through the same
:class:`~fr5_rl.control.JointCommandShaper` the ROS policy node uses, the simulated position
controller tracks it for ``control_dt`` seconds, and the observation is built by the same
:class:`~fr5_rl.observation.ObservationBuilder` from measured joint state.
"""
from __future__ import annotations

import math
from collections import deque
from typing import Any, Dict, List, Mapping, Optional, Tuple

import gymnasium as gym
import numpy as np
import pybullet as p
from gymnasium import spaces

from .config import load_env_config, load_robot_spec, simulation_settings
from .control import ACTION_SIZE, JointCommandShaper, finite_values
from .kinematics import ForwardKinematics
from .observation import ObservationBuilder
from .sim.robot import FR5Robot
from .sim.world import PyBulletWorld
from .tasks import GraspTask, ReachTask, Task, TaskState
from .transforms import quaternion_z_axis

TASKS = {"reach": ReachTask, "grasp": GraspTask}
_REWARD_KEYS = {name: f"reward_{name}" for name in ("success", "collision", "progress", "action")}
_TERM_KEYS = {name: f"term_{name}" for name in ("approach", "orientation", "gripper", "lift")}


class FR5Env(gym.Env):
    """FR5 + gripper in PyBullet. Observation and action layouts: see fr5_rl.observation and
    fr5_rl.control. ``info`` carries ``is_success``, ``failure`` and every reward part.

    Args:
        task: "reach" or "grasp".
        config: overrides merged into ``config/env.yaml`` (unknown keys are refused).
        render_mode: None, "rgb_array" (headless TinyRenderer) or "human" (PyBullet GUI).
    """

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 50}

    def __init__(self, task: str = "reach", config: Optional[Mapping[str, Any]] = None,
                 render_mode: Optional[str] = None) -> None:
        super().__init__()
        if task not in TASKS:
            raise ValueError(f"unknown task '{task}'; choose one of {sorted(TASKS)}")
        if render_mode not in (None, "rgb_array", "human"):
            raise ValueError(f"render_mode must be None, 'rgb_array' or 'human', got {render_mode!r}")
        self.cfg = load_env_config(config)
        self.robot_spec = load_robot_spec()
        self.render_mode = render_mode
        self.control_dt = float(self.cfg["simulation"]["control_dt"])
        self.task: Task = TASKS[task](self.cfg, self.robot_spec.max_opening_width)
        self.kinematics = ForwardKinematics(self.robot_spec)
        self.shaper = JointCommandShaper(self.robot_spec, self.cfg["action"], self.control_dt)
        self.observation_builder = ObservationBuilder(self.robot_spec, self.cfg["observation"], self.task.include_lift)
        self.observation_space = spaces.Box(-1.0, 1.0, (self.observation_builder.size,), dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, (ACTION_SIZE,), dtype=np.float32)

        sim_cfg = simulation_settings(self.cfg, task)
        self._physics_dt = float(sim_cfg["physics_dt"])
        self.world = PyBulletWorld(sim_cfg, gui=render_mode == "human", renders=render_mode is not None)
        self.world.add_table(self.cfg["table"])
        self.robot = FR5Robot(self.world.client, self.robot_spec, sim_cfg)
        # The robot stands on the table: its base never counts as touching it.
        for link in (-1, 0):
            p.setCollisionFilterPair(self.robot.body, self.world.table_id, link, -1, 0,
                                     physicsClientId=self.world.client)
        obj = self.cfg["object"]
        self._object_rest_z = float(self.cfg["table"]["top_height"])  # set per episode with the object's size
        self._object_start: Tuple[float, float, float] = (0.0, 0.0, self._object_rest_z)
        self._gripper_command_width = self.robot_spec.max_opening_width
        self._action_queue: deque = deque()
        self._latency_steps = 0
        self._obs_noise_std = 0.0
        self._steps = 0
        self._state: Optional[TaskState] = None  # the last one observed
        self._workspace = (tuple(self.cfg["workspace"]["low"]), tuple(self.cfg["workspace"]["high"]))
        self._object_cfg = obj

    # ------------------------------------------------------------------ gym API
    def reset(self, *, seed: Optional[int] = None, options: Optional[Dict[str, Any]] = None
              ) -> Tuple[np.ndarray, Dict[str, Any]]:
        super().reset(seed=seed)
        rng = self.np_random
        self._apply_randomisation(rng)
        low, high = np.asarray(self._object_cfg["region_low"]), np.asarray(self._object_cfg["region_high"])
        xy = rng.uniform(low, high) if not options or "object_xy" not in options else np.asarray(options["object_xy"])
        self._object_start = (float(xy[0]), float(xy[1]), self._object_rest_z)
        self.world.place_object(self._object_start, yaw=float(rng.uniform(-np.pi, np.pi)))

        noise = float(self.cfg[self.task.name]["start_joint_noise"])
        start = self.robot_spec.home_joint_positions + rng.uniform(-noise, noise, 6)
        start = np.clip(start, self.robot_spec.lower_limits, self.robot_spec.upper_limits)
        self._gripper_command_width = self.robot_spec.max_opening_width
        self.robot.reset(start, self._gripper_command_width)
        self.shaper.reset()
        self.task.reset()
        self._action_queue.clear()
        self._steps = 0
        state, obs = self._observe()
        self.task.prime(state)
        return obs, {"is_success": False, "failure": None, "object_start": np.array(self._object_start)}

    def step(self, action: np.ndarray) -> Tuple[np.ndarray, float, bool, bool, Dict[str, Any]]:
        # Plain floats from here on: for seven values that is faster than numpy, and this runs
        # thousands of times a second.
        values = finite_values(action, ACTION_SIZE, "the action")
        values = [1.0 if value > 1.0 else (-1.0 if value < -1.0 else value) for value in values]
        applied = self._delayed(values)
        # The joint state measured by the last observation is still current: nothing moved since.
        # Both lists hold finite floats (the observation refuses anything else), so the shaper's
        # checks are not repeated.
        targets = self.shaper.targets_from_floats(applied, self._state.joint_positions)
        self._gripper_command_width = self.shaper.gripper_width(applied)
        self.robot.command(targets, self._gripper_command_width)
        self.world.step()
        self._steps += 1

        state, obs = self._observe()
        outcome = self.task.judge(state, self.control_dt)
        parts = self.task.reward(outcome, values)
        terminated = outcome.success or outcome.failure is not None
        truncated = not terminated and self._steps >= self.task.max_steps
        info: Dict[str, Any] = {"is_success": outcome.success,
                                "failure": "timeout" if truncated else outcome.failure}
        for name, value in parts.items():
            info[_REWARD_KEYS[name]] = value
        for name, value in outcome.terms.items():
            info[_TERM_KEYS[name]] = value
        if self.render_mode == "human":
            self.render()
        return obs, sum(parts.values()), terminated, truncated, info

    def render(self) -> Optional[np.ndarray]:
        if self.render_mode == "rgb_array":
            return self.world.render()
        return None

    def close(self) -> None:
        self.world.close()

    # ------------------------------------------------------------------ inspection
    def tcp_position(self) -> np.ndarray:
        """tcp position in the world (= base_link) frame, metres, from the simulator."""
        return self.robot.tcp_pose_from_simulator()[0]

    def object_position(self) -> np.ndarray:
        """Object centre in the world (= base_link) frame, metres."""
        return np.array(self.world.object_pose()[0])

    @property
    def gripper_command_width(self) -> float:
        """Opening width (m) the last action commanded."""
        return self._gripper_command_width

    def joint_positions(self) -> np.ndarray:
        """Measured arm joint angles (rad), controller order."""
        return self.robot.joint_state()[0]

    # ------------------------------------------------------------------ internals
    def _delayed(self, action: List[float]) -> List[float]:
        """Apply the configured action latency (whole control steps; 0 = none)."""
        if self._latency_steps == 0:
            return action
        self._action_queue.append(action)
        if len(self._action_queue) <= self._latency_steps:
            # Until the first action arrives the arm holds and the gripper keeps its command.
            return [0.0] * (ACTION_SIZE - 1) + [self.shaper.gripper_action(self._gripper_command_width)]
        return self._action_queue.popleft()

    def task_state(self) -> TaskState:
        """Ground-truth state the task judges (also used by the ROS simulator node).

        Four simulator queries in all: joints, tcp link, object, contacts.
        """
        q, qd, width, tcp_position, tcp_quaternion = self.robot.measure()
        object_position, object_quaternion = self.world.object_pose()
        table, obj, finger_links = self.world.table_id, self.world.object_id, self.robot.finger_links
        table_contact = arm_object_contact = False
        pads = set()
        for contact in self.robot.contacts():  # one query for all of the robot's contacts
            if contact[2] == table:
                table_contact = True
            elif contact[2] == obj:
                if contact[3] in finger_links:
                    pads.add(contact[3])
                else:
                    arm_object_contact = True
        x, y, z = tcp_position
        (x_low, y_low, z_low), (x_high, y_high, z_high) = self._workspace
        return TaskState(
            joint_positions=q, joint_velocities=qd, tcp_position=tcp_position,
            tcp_approach_axis=quaternion_z_axis(tcp_quaternion), gripper_width=width,
            tcp_to_object_distance=math.dist(object_position, tcp_position),
            object_position=object_position, object_up_axis=quaternion_z_axis(object_quaternion),
            object_start_position=self._object_start, robot_table_contact=table_contact,
            arm_object_contact=arm_object_contact, fingers_object_contact=len(pads),
            tcp_in_workspace=x_low <= x <= x_high and y_low <= y <= y_high and z_low <= z <= z_high,
        )

    def _observe(self) -> Tuple[TaskState, np.ndarray]:
        self._state = state = self.task_state()
        q, tcp_position, tcp_axis, object_position = (
            state.joint_positions, state.tcp_position, state.tcp_approach_axis, state.object_position)
        if self._obs_noise_std > 0.0:
            rng = self.np_random
            q = np.asarray(q) + rng.normal(0.0, self._obs_noise_std, 6)
            object_position = np.asarray(object_position) + rng.normal(0.0, self._obs_noise_std, 3)
            # The tcp pose follows the noisy joints, as FK of a noisy encoder reading would.
            tcp_position, tcp_rotation = self.kinematics.tcp_pose(q)
            tcp_axis = tcp_rotation[:, 2]
        obs = self.observation_builder.build_from(
            q, state.joint_velocities, state.gripper_width, self._gripper_command_width, tcp_position, tcp_axis,
            object_position, object_position[2] - self._object_rest_z,
        )
        return state, obs

    @property
    def object_rest_z(self) -> float:
        """z (m, base_link) of the object's centre when it stands on the table."""
        return self._object_rest_z

    def _apply_randomisation(self, rng: np.random.Generator) -> None:
        """Object size/mass/friction, joint damping, latency, observation noise (if enabled)."""
        obj, rnd = self._object_cfg, self.cfg["randomisation"]
        on = bool(rnd["enabled"])
        size = rng.uniform(*rnd["object_size_scale"]) if on else 1.0
        mass = float(obj["mass"]) * (rng.uniform(*rnd["object_mass_scale"]) if on else 1.0)
        friction = float(obj["lateral_friction"]) * (rng.uniform(*rnd["friction_scale"]) if on else 1.0)
        if obj["shape"] == "cylinder":
            dims = (float(obj["radius"]) * size, float(obj["height"]) * size)
            half_height = dims[1] / 2.0
        else:
            dims = (float(obj["half_extent"]) * size,)
            half_height = dims[0]
        self._object_rest_z = float(self.cfg["table"]["top_height"]) + half_height
        self.world.set_object(str(obj["shape"]), dims, mass, friction)
        self.robot.set_joint_damping(rng.uniform(*rnd["joint_damping"]) if on else 0.0)
        # The simulated position controller tracks differently at other physics steps: drawing
        # the step per episode keeps a policy from relying on one simulator's exact response.
        choices = rnd.get("physics_dt_choices") or []
        physics_dt = float(rng.choice(choices)) if on and choices else self._physics_dt
        if physics_dt != self.world.physics_dt:
            self.world.set_physics_dt(physics_dt, self.control_dt)
        lo, hi = (int(v) for v in rnd["action_latency_steps"])
        self._latency_steps = int(rng.integers(lo, hi + 1)) if on else 0
        self._obs_noise_std = float(rnd["observation_noise_std"]) if on else 0.0
