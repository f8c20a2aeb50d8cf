"""Gymnasium environments FR5Reach-v0 and FR5Grasp-v0: a world, a robot and a task composed.

One ``step`` is one 50 Hz control period: the action goes through the same
:class:`~fr5_rl.control.JointCommandShaper` the ROS policy node uses, the simulated position
controller tracks it for ``control_dt`` seconds, and the observation is built by the same
:class:`~fr5_rl.observation.ObservationBuilder` from measured joint state.

Beside the gymnasium API, :class:`FR5Env` offers what a real-time stand-in for the arm (the
ROS simulator node) needs, without reaching into the simulator: :meth:`FR5Env.advance_physics`,
:meth:`FR5Env.judge_period`, :meth:`FR5Env.joint_states`, :meth:`FR5Env.object_pose` and
:meth:`FR5Env.scene`. Only :mod:`fr5_rl.sim` talks to PyBullet.
"""
from __future__ import annotations

import dataclasses
import os
import copy
import math
from collections import deque
from dataclasses import dataclass
from typing import Any, Dict, List, Mapping, NamedTuple, Optional, Sequence, Tuple, Union

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.envs.registration import EnvSpec

from .config import load_robot_spec
from .env_config import EnvConfig, load_env_config
from .control import ACTION_SIZE, JointCommandShaper, finite_values
from .gripper import BridgedGripper, load_bridge_timing
from .kinematics import ForwardKinematics
from .motion_guard import MotionGuard, load_guard_settings
from .observation import ActionHistory, DelayedTarget, ObservationBuilder, velocity_from_positions
from .sim.gripper_chain import EmulatedGripperChain
from .sim.robot import FR5Robot
from .sim.servo import FirstOrderResponse
from .sim.world import PyBulletWorld
from .tasks import GraspTask, ReachTask, Task, TaskOutcome, TaskState
from .transforms import quaternion_z_axis

TASKS = {"reach": ReachTask, "grasp": GraspTask}
_REWARD_KEYS = {name: f"reward_{name}" for name in ("success", "collision", "failure", "progress", "action")}
_TERM_KEYS = {name: f"term_{name}" for name in ("approach", "orientation", "gripper", "lift")}


class EpisodeVerdict(NamedTuple):
    """How one control period left the episode (see :meth:`FR5Env.judge_period`).

    :param success: the task's success test passed this period.
    :param failure: why the episode failed (the task's reason, e.g. ``"collision"``, or
        ``"timeout"`` when the step limit ended it), else None.
    :param terminated: the episode ended by success or a task failure (gymnasium's
        ``terminated``).
    :param truncated: the step limit ended it first (gymnasium's ``truncated``; ``failure``
        is then ``"timeout"``).
    :param steps: control periods judged since the reset, this one included.
    :param outcome: the task's own verdict, with the unweighted shaping terms the reward
        is made of (its ``failure`` never says ``"timeout"``).
    """

    success: bool
    failure: Optional[str]
    terminated: bool
    truncated: bool
    steps: int
    outcome: TaskOutcome

    @property
    def ended(self) -> bool:
        """The episode is over (``terminated or truncated``)."""
        return self.terminated or self.truncated

    @property
    def terms(self) -> Dict[str, float]:
        """The task's unweighted shaping terms of this period, by name."""
        return self.outcome.terms


class JointStates(NamedTuple):
    """Measured state of the eight joints, by name, as ``sensor_msgs/JointState`` carries it.

    :param names: the arm joints ``j1`` .. ``j6`` (controller order), then the two finger joints.
    :param positions: arm angles (rad), then each finger's travel from closed (m; the opening
        width is their sum).
    :param velocities: arm (rad/s), then fingers (m/s).
    """

    names: Tuple[str, ...]
    positions: Tuple[float, ...]
    velocities: Tuple[float, ...]


class Pose(NamedTuple):
    """A pose in a named frame.

    :param position: (x, y, z) in metres.
    :param quaternion: (x, y, z, w), unit.
    :param frame_id: the frame both are expressed in (``base_link`` here).
    """

    position: Tuple[float, float, float]
    quaternion: Tuple[float, float, float, float]
    frame_id: str


@dataclass(frozen=True)
class SceneDescription:
    """The static scene of the current episode, for drawing it (e.g. rviz markers).

    :param frame_id: the frame of every position below (``base_link``, the world frame).
    :param table_size: table box (x, y, thickness) in metres.
    :param table_center: centre (m) of the table box.
    :param table_top_height: z (m) of the table's top face.
    :param object_shape: ``"cylinder"`` or ``"box"``.
    :param object_dims: as placed this episode (after any size randomisation): (radius,
        height) of a cylinder or (half_extent,) of a cube, metres.
    :param object_rest_z: z (m) of the object's centre when it stands on the table.
    """

    frame_id: str
    table_size: Tuple[float, float, float]
    table_center: Tuple[float, float, float]
    table_top_height: float
    object_shape: str
    object_dims: Tuple[float, ...]
    object_rest_z: float

    @property
    def object_size(self) -> Tuple[float, float, float]:
        """Extent (m) of the object along its own x, y and z axes (its bounding box)."""
        if self.object_shape == "cylinder":
            radius, height = self.object_dims
            return (2.0 * radius, 2.0 * radius, height)
        return (2.0 * self.object_dims[0],) * 3


@dataclass(frozen=True)
class SavedEpisode:
    """An episode saved by :meth:`FR5Env.save_state`: the world's simulator state, the
    environment's per-episode attributes, the task's and command shaper's, and the robot's
    command state."""

    simulation: Tuple[int, bool]
    environment: Dict[str, Any]
    parts: Tuple[Dict[str, Any], Dict[str, Any]]
    robot: Tuple[float, Optional[float]]


# What FR5Env.save_state leaves out: built once and never changed by a step (the simulator's
# handles, configuration, spaces), saved apart (the task, the shaper), or the random stream.
_SHARED_STATE = frozenset({
    "world", "robot", "cfg", "robot_spec", "task", "kinematics", "shaper", "observation_builder",
    "observation_space", "action_space", "render_mode", "metadata", "spec", "_spec", "_bridge_model", "_np_random", "_np_random_seed",
})


class FR5Env(gym.Env):
    """FR5 + gripper in PyBullet. Observation and action layouts: see fr5_rl.observation and
    fr5_rl.control. ``info`` carries ``is_success``, ``failure`` and every reward part.

    Args:
        task: "reach" or "grasp".
        config: overrides merged into ``config/env.yaml`` (unknown keys are refused), or an
            :class:`~fr5_rl.env_config.EnvConfig` already loaded.
        render_mode: None, "rgb_array" (headless TinyRenderer) or "human" (PyBullet GUI).
        robot: the arm (``fr5``, ``fr10``, …: ``config/robots/``), the same as ``config={"robot": …}``;
            None: the config's (``fr5`` by default).
    """

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 50}
    _spec: Optional[EnvSpec] = None

    def __init__(self, task: str = "reach", config: Union[EnvConfig, Mapping[str, Any], None] = None,
                 render_mode: Optional[str] = None, robot: Optional[str] = None) -> None:
        super().__init__()
        if task not in TASKS:
            raise ValueError(f"unknown task '{task}'; choose one of {sorted(TASKS)}")
        if render_mode not in (None, "rgb_array", "human"):
            raise ValueError(f"render_mode must be None, 'rgb_array' or 'human', got {render_mode!r}")
        # What this machine can render: without an X display no "human" window (gymnasium's
        # check_env tries every mode listed here).
        self.metadata = {**self.metadata, "render_modes": ["rgb_array"] + (["human"] if os.environ.get("DISPLAY") else [])}
        if isinstance(config, EnvConfig):
            if robot is not None and robot != config.robot:
                raise ValueError(f"robot='{robot}' contradicts the configuration's robot '{config.robot}'")
            self.cfg = config
        else:
            self.cfg = load_env_config({**(config or {}), **({"robot": robot} if robot is not None else {})})
        self.robot_spec = load_robot_spec(self.cfg.robot)
        self.render_mode = render_mode
        self.control_dt = self.cfg.simulation.control_dt
        self.task: Task = TASKS[task](self.cfg, self.robot_spec.max_opening_width)
        self.kinematics = ForwardKinematics(self.robot_spec)
        self.shaper = JointCommandShaper(self.robot_spec, self.cfg.action, self.control_dt)
        self.observation_builder = ObservationBuilder(self.robot_spec, self.cfg.observation, self.task.include_lift)
        self.observation_space = spaces.Box(-1.0, 1.0, (self.observation_builder.size,), dtype=np.float32)
        self._action_history = ActionHistory(self.observation_builder.previous_actions)
        self.action_space = spaces.Box(-1.0, 1.0, (ACTION_SIZE,), dtype=np.float32)

        sim_cfg = self.cfg.simulation_for(task)
        self._physics_dt = sim_cfg.physics_dt
        self.world = PyBulletWorld(sim_cfg, gui=render_mode == "human", renders=render_mode is not None)
        self.world.add_table(self.cfg.table)
        self.robot = FR5Robot(self.world.client, self.robot_spec, sim_cfg)
        self.robot.stand_on(self.world.table_id)  # its base never counts as touching the table
        self._object_rest_z = self.cfg.table.top_height  # set per episode with the object's size
        self._object_dims: Tuple[float, ...] = ()  # set per episode
        self._joint_state_names = tuple(self.robot_spec.joint_names) + tuple(self.robot_spec.finger_joint_names)
        self._object_start: Tuple[float, float, float] = (0.0, 0.0, self._object_rest_z)
        self._gripper_command_width = self.robot_spec.max_opening_width
        # The width the agent last sent: what the observation shows. Behind action latency the
        # gripper is still carrying out an older one (_gripper_command_width); the ROS node, too,
        # knows only what it sent.
        self._sent_gripper_width = self._gripper_command_width
        self._action_queue: deque = deque()
        self._latency_steps = 0
        self._gripper_latency_steps: Optional[int] = None  # None: the arm's latency
        self._obs_noise_std = 0.0
        # Real-time timing within a period (randomisation.command_delay_s, observation_age_s):
        # ranges (s) drawn every step, and the command standing until a delayed one takes over.
        self._command_delay_range = (0.0, 0.0)
        self._observation_age_range = (0.0, 0.0)
        self._period_timing = False  # either range above is non-zero, or a response: step's slower path
        # randomisation.response_time_constant_s: the driver's lag in episodes with the timing, or None.
        self._response: Optional[FirstOrderResponse] = None
        self._standing_command: Tuple[Sequence[float], float] = ((), 0.0)
        self._steps = 0
        self._state: Optional[TaskState] = None  # the last one observed
        # observation.joint_velocity_source: positions: the last observed sample (positions,
        # time s) and estimate, None at the start of an episode.
        self._velocities_from_positions = self.cfg.observation.joint_velocity_source == "positions"
        self._velocity_sample: Optional[Tuple[Sequence[float], float, List[float]]] = None
        self._workspace = (tuple(self.cfg.workspace.low), tuple(self.cfg.workspace.high))
        # randomisation.gripper_bridge_share: the gripper behind the bridge in this episode, or None.
        self._bridge_model: Union[BridgedGripper, EmulatedGripperChain, None] = None
        if self.cfg.randomisation.enabled and self.cfg.randomisation.gripper_bridge_share > 0.0:
            max_width = self.robot_spec.max_opening_width
            self._bridge_model = (EmulatedGripperChain.from_config(max_width)
                                  if self.cfg.randomisation.gripper_bridge_emulation
                                  else BridgedGripper(load_bridge_timing(), max_width))
        self._bridge: Union[BridgedGripper, EmulatedGripperChain, None] = None
        # randomisation.guard_share: the policy node's motion guard limits this episode's commands.
        self._guard: Optional[MotionGuard] = None
        self._guard_on = False
        if self.cfg.randomisation.enabled and self.cfg.randomisation.guard_share > 0.0:
            self._guard = MotionGuard(self.robot_spec, load_guard_settings(), self.robot_spec.home_joint_positions,
                                      self.cfg.task(task).start_joint_noise, self.control_dt)
        # randomisation.target_share: the object seen through the camera's timing, or None.
        self._target: Optional[DelayedTarget] = None
        self._held = None  # hold_object's constraint (the camera's calibration), or None
        # randomisation.target_hidden_radius; -1: never hidden (a distance is never below it)
        self._target_hidden_radius = self.cfg.randomisation.target_hidden_radius or -1.0

    @property
    def spec(self) -> Optional[EnvSpec]:
        """gymnasium's spec, with ``max_episode_steps`` the configured task's ``max_steps``: the
        environment truncates itself there (a TimeLimit fixed at registration would cut an
        episode the configuration makes longer)."""
        return self._spec

    @spec.setter
    def spec(self, value: Optional[EnvSpec]) -> None:
        if value is not None and value.max_episode_steps is None and hasattr(self, "cfg"):
            value = dataclasses.replace(value, max_episode_steps=self.cfg.task(self.task.name).max_steps)
        self._spec = value

    # ------------------------------------------------------------------ gym API
    def reset(self, *, seed: Optional[int] = None, options: Optional[Dict[str, Any]] = None
              ) -> Tuple[np.ndarray, Dict[str, Any]]:
        """A new episode. ``options``: ``object_xy`` (m, base_link) places the object there;
        ``arm_positions`` (rad, j1..j6) keeps the arm there instead of a start drawn around home
        (the random draws are made either way, so a seed places the same object)."""
        super().reset(seed=seed)
        rng = self.np_random
        self._apply_randomisation(rng)
        low, high = np.asarray(self.cfg.object.region_low), np.asarray(self.cfg.object.region_high)
        given = bool(options) and "object_xy" in options
        xy = np.asarray(options["object_xy"]) if given else rng.uniform(low, high)
        focus = self.cfg.randomisation
        # Drawn only when on, so that with the focus off a seed places the same object as before.
        if not given and focus.enabled and focus.placement_focus_share > 0.0 \
                and rng.uniform() < focus.placement_focus_share:
            xy = rng.uniform(np.asarray(focus.placement_focus_low), np.asarray(focus.placement_focus_high))
        self._object_start = (float(xy[0]), float(xy[1]), self._object_rest_z)
        self.world.place_object(self._object_start, yaw=float(rng.uniform(-np.pi, np.pi)))

        noise = self.cfg.task(self.task.name).start_joint_noise
        start = self.robot_spec.home_joint_positions + rng.uniform(-noise, noise, 6)
        if options and "arm_positions" in options:
            # The arm stays where it is (a real arm between episodes: only the object is placed);
            # the draw above still happens, so the object of every seed is gym's.
            start = finite_values(options["arm_positions"], 6, "options['arm_positions']")
        start = np.clip(start, self.robot_spec.lower_limits, self.robot_spec.upper_limits)
        self._gripper_command_width = self._sent_gripper_width = self.robot_spec.max_opening_width
        self.robot.reset(start, self._gripper_command_width)
        if options and "arm_positions" in options and not given:
            self._place_clear_of_arm(rng)
        self.shaper.reset()
        self._action_history.reset()
        self.task.reset()
        self._action_queue.clear()
        self._standing_command = (tuple(start), self._gripper_command_width)
        if self._response is not None:
            self._response.reset(start)
        self._steps = 0
        self._velocity_sample = None
        state, obs = self._observe()
        self.task.prime(state)
        return obs, {"is_success": False, "failure": None, "object_start": np.array(self._object_start)}

    def _place_clear_of_arm(self, rng: np.random.Generator) -> None:
        """With the arm kept where it stands: draw the object's place again (after every other
        draw, so a seed whose object lies clear is placed as gym places it) while it would lie
        within ``object.placement_clearance`` of the arm or gripper.

        :raises RuntimeError: no clear place in ``object.placement_attempts`` draws (the arm
            covers the placement region: move it away first).
        """
        obj = self.cfg.object
        low, high = np.asarray(obj.region_low), np.asarray(obj.region_high)
        for _ in range(obj.placement_attempts):
            if not self.robot.comes_within(self.world.object_id, obj.placement_clearance):
                return
            xy = rng.uniform(low, high)
            self._object_start = (float(xy[0]), float(xy[1]), self._object_rest_z)
            self.world.place_object(self._object_start, yaw=float(rng.uniform(-np.pi, np.pi)))
        if self.robot.comes_within(self.world.object_id, obj.placement_clearance):
            raise RuntimeError(f"no place for the object clear of the arm in {obj.placement_attempts} draws: "
                               "the arm covers the placement region; move it away before the reset")

    def step(self, action: np.ndarray) -> Tuple[np.ndarray, float, bool, bool, Dict[str, Any]]:
        # Plain floats from here on: for seven values that is faster than numpy, and this runs
        # thousands of times a second.
        values = finite_values(action, ACTION_SIZE, "the action")
        values = [1.0 if value > 1.0 else (-1.0 if value < -1.0 else value) for value in values]
        if self._action_history.count:
            self._action_history.push(values)  # what the agent sent, before any delay
        self._sent_gripper_width = sent_width = self.shaper.gripper_width(values)
        applied = self._delayed(values)
        # Targets are offsets from the joint state the last observation saw (as on the robot,
        # where that is the newest /joint_states message, however old). Both lists hold finite
        # floats (the observation refuses anything else), so the shaper's checks are not repeated.
        targets = self.shaper.targets_from_floats(applied, self._observed_joint_positions)
        if self._guard_on:  # the ramp-in from the episode's start and the joint-limit margin, as deployed
            targets = self._guard.limit(targets, self._observed_joint_positions, self._steps * self.control_dt).tolist()
        width = sent_width if applied is values else self.shaper.gripper_width(applied)
        if self._bridge is not None:
            width = self._bridge.command(width, self._steps * self.control_dt)
        early = self._run_period(targets, width)
        measured_early, age = early if early is not None else (None, 0.0)
        now = (self._steps + 1) * self.control_dt
        state, obs = self._observe(measured_early, now - age, now)
        success, failure, terminated, truncated, _, outcome = self.judge_period(state)
        parts = self.task.reward(outcome, values)
        info: Dict[str, Any] = {"is_success": success, "failure": failure}
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

    # ------------------------------------------------------------------ saved states
    def save_state(self) -> SavedEpisode:
        """The episode as it stands, to go on from later with :meth:`restore_state`: the
        simulator's state and everything of this environment's that a step changes (the command
        shaper's filter, latency queues, the task's timers and potential, the step count, ...).

        Restoring is only meaningful in the same episode's world (no :meth:`reset` in between:
        a reset builds a new object). The random stream is not saved: after a restore the episode
        goes on with fresh draws (in a plain configuration steps draw nothing, and a restored
        episode goes on exactly as the saved one did). A saved state holds simulator memory until
        :meth:`discard_state`.
        """
        own = {name: copy.deepcopy(value) for name, value in self.__dict__.items() if name not in _SHARED_STATE}
        parts = (self.task.__dict__, self.shaper.__dict__)
        return SavedEpisode(self.world.save_state(), own, tuple(copy.deepcopy(part) for part in parts),
                            self.robot.save_command_state())

    def restore_state(self, saved: SavedEpisode) -> None:
        """Go back to a state from :meth:`save_state` (it stays saved: restore it again or discard it)."""
        self.world.restore_state(saved.simulation)
        self.__dict__.update(copy.deepcopy(saved.environment))
        task_state, shaper_state = (copy.deepcopy(part) for part in saved.parts)
        self.task.__dict__.update(task_state)
        self.shaper.__dict__.update(shaper_state)
        self.robot.restore_command_state(saved.robot)

    def discard_state(self, saved: SavedEpisode) -> None:
        """Free the simulator memory of a state from :meth:`save_state`."""
        self.world.discard_state(saved.simulation)

    # ------------------------------------------------------------------ inspection
    def tcp_position(self) -> np.ndarray:
        """tcp position in the world (= base_link) frame, metres, from the simulator."""
        return self.robot.tcp_pose_from_simulator()[0]

    def object_position(self) -> np.ndarray:
        """Object centre in the world (= base_link) frame, metres."""
        return np.array(self.world.object_pose()[0])

    @property
    def gripper_command_width(self) -> float:
        """Opening width (m) the last action (or :meth:`advance_physics`) commanded."""
        return self._gripper_command_width

    def joint_positions(self) -> np.ndarray:
        """Measured arm joint angles (rad), controller order."""
        return self.robot.joint_state()[0]

    def joint_states(self) -> JointStates:
        """Measured positions and velocities of the six arm joints and the two finger joints,
        by name (one simulator query), for ``/joint_states``.

        :return: names ``j1`` .. ``j6`` then the finger joints; arm in rad and rad/s, fingers in
            m and m/s (see :class:`JointStates`).
        """
        positions, velocities = self.robot.joint_lists_with_fingers()
        return JointStates(self._joint_state_names, tuple(positions), tuple(velocities))

    def object_pose(self) -> Pose:
        """The object's pose as the simulator has it (ground truth, what a camera would see).

        :return: centre position (m) and orientation quaternion (x, y, z, w) in base_link.
        """
        position, quaternion = self.world.object_pose()
        return Pose(tuple(position), tuple(quaternion), self.robot_spec.base_frame)

    def scene(self) -> SceneDescription:
        """The table and the object as placed this episode (sizes after randomisation), in
        base_link: what a viewer needs to draw the static scene. No simulator query.

        :return: see :class:`SceneDescription`.
        """
        table = self.cfg.table
        sx, sy, thickness = table.size
        cx, cy = table.center_xy
        top = table.top_height
        return SceneDescription(
            frame_id=self.robot_spec.base_frame, table_size=(sx, sy, thickness),
            table_center=(cx, cy, top - thickness / 2.0), table_top_height=top,
            object_shape=self.cfg.object.shape, object_dims=tuple(float(d) for d in self._object_dims),
            object_rest_z=self._object_rest_z,
        )

    # ------------------------------------------------------------------ real-time stepping
    @property
    def physics_dt(self) -> float:
        """Duration (s) of one physics step, the unit :meth:`advance_physics` advances by.

        It divides :attr:`control_dt`; with ``randomisation.physics_dt_choices`` it is drawn
        anew at every reset.
        """
        return self.world.physics_dt

    def advance_physics(self, arm_targets: Sequence[float], gripper_width: float) -> None:
        """Advance the simulation by one physics step (:attr:`physics_dt` seconds) with the
        position controllers tracking the given targets: the finer-grained alternative to
        :meth:`step` for running the arm in real time behind a driver interface.

        The targets go to the joints as they are (no action scaling, smoothing or step
        limit), so the caller keeps them inside the joint limits. Call :meth:`judge_period`
        after every :attr:`control_dt` of simulated time to judge the episode. Within one
        episode use either this or :meth:`step`, not both.

        :param arm_targets: (6,) joint position targets (rad), controller order j1 .. j6.
        :param gripper_width: wanted opening width (m), 0 (closed) .. the maximum opening;
            the fingers move toward it at the gripper's rated speed.
        """
        self._gripper_command_width = float(gripper_width)
        self.robot.command(arm_targets, gripper_width, period=self.world.physics_dt)
        self.world.step_physics()

    def advance_period(self, arm_targets: Sequence[float], gripper_width: float) -> None:
        """Advance the simulation by one control period (:attr:`control_dt` seconds) with one
        command standing throughout: what :meth:`step` does after shaping its action. A
        lockstep driver calls this, then :meth:`judge_period`, to reproduce :meth:`step`
        exactly from joint targets computed elsewhere (the ROS policy node).

        :param arm_targets: (6,) joint position targets (rad), controller order j1 .. j6, inside
            the joint limits.
        :param gripper_width: wanted opening width (m); the fingers ramp toward it at the
            gripper's rated speed.
        """
        self._gripper_command_width = float(gripper_width)
        self.robot.command(arm_targets, self._gripper_command_width)
        self.world.step()

    def hold_object(self, object_in_tcp: Sequence[float]) -> None:
        """Fix the object in the gripper, its centre at ``object_in_tcp`` (m, tcp frame), as a
        person's hand-over into the closed gripper leaves it (the camera's calibration); the
        episode is not judged meanwhile (the caller's business). :meth:`release_object` lets go."""
        from .sim.held_object import HeldObject

        self.release_object()
        self.world.wake_object()
        self._held = HeldObject(self.world.client, self.robot.body, self.robot.tcp_link, self.world.object_id,
                                [self.world.table_id])
        self._held.hold(object_in_tcp)

    def release_object(self) -> None:
        """Let go of an object held by :meth:`hold_object` (nothing if none is)."""
        held, self._held = self._held, None
        if held is not None:
            held.release()

    def judge_period(self, state: Optional[TaskState] = None) -> EpisodeVerdict:
        """Count and judge one control period of the episode: the task's success and failure
        tests, and the step limit (``"timeout"``). :meth:`step` calls it once per step; a
        real-time driver calls it after every :attr:`control_dt` of simulated time.

        Stateful, like the task: each call counts one more period (and the grasp task's hold
        timer runs), so call it exactly once per period. :meth:`reset` starts the count over.

        :param state: the state measured at the end of the period (:meth:`task_state`); None
            measures it now (four simulator queries).
        :return: the verdict; its ``steps`` counts the periods judged since the reset.
        """
        if state is None:
            self._state = state = self.task_state()
        self._steps = steps = self._steps + 1
        outcome = self.task.judge(state, self.control_dt)
        success, failure = outcome.success, outcome.failure
        terminated = success or failure is not None
        truncated = not terminated and steps >= self.task.max_steps
        return EpisodeVerdict(success, "timeout" if truncated else failure, terminated, truncated, steps, outcome)

    # ------------------------------------------------------------------ internals
    def _run_period(self, arm_targets: Sequence[float], gripper_width: float) -> Optional[Tuple[tuple, float]]:
        """One control period of :meth:`step`, with the real-time loop's timing if randomised:
        the previous command stands for the first ``command_delay`` of the period (a driver's
        servo cycle, a late command), and the observation is measured ``observation_age``
        before the period ends (a joint state published at a lower rate than the loop runs).

        :return: the robot's measurement (:meth:`FR5Robot.measure`) taken early and how long (s)
            before the period's end, or None when the observation is measured at its end.
        """
        if not self._period_timing:
            self.advance_period(arm_targets, gripper_width)
            return None
        substeps, physics_dt = self.world.substeps, self.world.physics_dt
        delay = self._draw_substeps(self._command_delay_range, substeps - 1)
        age = self._draw_substeps(self._observation_age_range, substeps - 1)
        if self._response is not None:
            return self._run_period_with_response(arm_targets, gripper_width, delay, age)
        if delay == 0 and age == 0:
            self.advance_period(arm_targets, gripper_width)
            self._standing_command = (arm_targets, gripper_width)
            return None
        measured = None
        if delay:
            self.robot.command(*self._standing_command, period=delay * physics_dt)
        for substep in range(substeps):
            if substep == delay:
                self.robot.command(arm_targets, gripper_width, period=(substeps - delay) * physics_dt)
            if substep == substeps - age:
                measured = self.robot.measure()
            self.world.step_physics()
        self._gripper_command_width = float(gripper_width)
        self._standing_command = (arm_targets, gripper_width)
        return (measured, age * physics_dt) if measured is not None else None

    def _run_period_with_response(self, arm_targets: Sequence[float], gripper_width: float, delay: int,
                                  age: int) -> Optional[Tuple[tuple, float]]:
        """:meth:`_run_period` behind a driver's response: every physics step the joints get the
        lagged targets, as the simulator node gives them (one motor call per step)."""
        physics_dt, measured = self.world.physics_dt, None
        substeps = self.world.substeps
        for substep in range(substeps):
            targets, width = self._standing_command if substep < delay else (arm_targets, gripper_width)
            self.robot.command(self._response.targets_for_step(targets), width, period=physics_dt)
            if substep == substeps - age and age:
                measured = self.robot.measure()
            self.world.step_physics()
        self._gripper_command_width = float(gripper_width)
        self._standing_command = (arm_targets, gripper_width)
        return (measured, age * physics_dt) if measured is not None else None

    def _draw_substeps(self, seconds_range: Tuple[float, float], most: int) -> int:
        """A duration drawn uniformly from ``seconds_range``, in whole physics steps."""
        low, high = seconds_range
        if high <= 0.0:
            return 0
        # numpy's uniform(low, high) is low + (high - low) * random(): the same draw, the same
        # bits, without its argument handling (two draws every step).
        seconds = low + (high - low) * self.np_random.random()
        return min(int(round(seconds / self.world.physics_dt)), most)

    def _delayed(self, action: List[float]) -> List[float]:
        """Apply the configured action latency (whole control steps; 0 = none): the arm
        ``_latency_steps`` behind, the gripper ``_gripper_latency_steps`` (None: the arm's). The
        queue keeps the newest actions, newest last."""
        arm = self._latency_steps
        gripper = arm if self._gripper_latency_steps is None else self._gripper_latency_steps
        if arm == gripper == 0:
            return action
        queue = self._action_queue
        queue.append(action)
        while len(queue) > max(arm, gripper) + 1:
            queue.popleft()
        # Until its first action arrives the arm holds and the gripper keeps its command.
        arm_part = queue[-1 - arm][:ACTION_SIZE - 1] if len(queue) > arm else [0.0] * (ACTION_SIZE - 1)
        gripper_part = (queue[-1 - gripper][ACTION_SIZE - 1] if len(queue) > gripper
                        else self.shaper.gripper_action(self._gripper_command_width))
        return [*arm_part, gripper_part]

    def task_state(self) -> TaskState:
        """Ground-truth state the task judges (also read by the scripted expert).

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

    def held_as_the_camera_sees(self, state: TaskState) -> bool:
        """The object is in the hand as the detector's tracker decides it (then it is published
        in the tcp frame, without the camera's delay): the fingers closed to about the object's
        width, the tcp near its centre, the object lifted off its resting height
        (``randomisation.target_in_hand_*``, the tracker's thresholds).

        :param state: :meth:`task_state` of this moment.
        """
        rnd = self.cfg.randomisation
        return (state.gripper_width <= 2.0 * self._object_dims[0] + rnd.target_in_hand_width_margin
                and state.tcp_to_object_distance <= rnd.target_in_hand_radius
                and state.object_position[2] > self._object_rest_z + rnd.target_in_hand_lift)

    def _observe(self, measured_early: Optional[tuple] = None, sample_time: float = 0.0,
                 now: float = 0.0) -> Tuple[TaskState, np.ndarray]:
        """The task state now, and the observation: of the state now, or of the robot as
        ``measured_early`` (an older joint state; the object is seen now, or through the camera's
        timing). ``sample_time`` (s since the reset) is when the observed joint state was
        sampled, ``now`` the period's end."""
        self._state = state = self.task_state()
        q, tcp_position, tcp_axis, object_position = (
            state.joint_positions, state.tcp_position, state.tcp_approach_axis, state.object_position)
        velocities, width = state.joint_velocities, state.gripper_width
        if measured_early is not None:
            q, velocities, width, tcp_position, tcp_quaternion = measured_early
            tcp_axis = quaternion_z_axis(tcp_quaternion)
        self._observed_joint_positions = q
        if self._bridge is not None:
            width = self._bridge.observe(width, sample_time)
        if self._target is not None:
            object_position = self._target.observe(
                object_position, now, self.held_as_the_camera_sees(state),
                state.tcp_to_object_distance <= self._target_hidden_radius)
        tcp_jacobian = None
        if self._obs_noise_std > 0.0:
            rng = self.np_random
            q = (np.asarray(q) + rng.normal(0.0, self._obs_noise_std, 6)).tolist()
            object_position = (np.asarray(object_position) + rng.normal(0.0, self._obs_noise_std, 3)).tolist()
            # The tcp pose follows the noisy joints, as FK of a noisy encoder reading would. The
            # joint-step hint needs the same chain of the same joints: computed once for both
            # (the same arithmetic, so the same bits).
            if self.observation_builder.joint_step_hint is not None:
                tcp_jacobian = self.kinematics.tcp_jacobian(q)
                tcp_position, tcp_axis = tcp_jacobian[0], tcp_jacobian[1]
            else:
                tcp_position, tcp_axis = self.kinematics.tcp_position_and_axis(q)
        if self._velocities_from_positions:
            velocities = self._estimate_velocities(q, sample_time)
        obs = self.observation_builder.build_from(
            q, velocities, width, self._sent_gripper_width, tcp_position, tcp_axis,
            object_position, object_position[2] - self._object_rest_z, self._action_history.values(),
            tcp_jacobian=tcp_jacobian,
        )
        return state, obs

    def _estimate_velocities(self, positions: Sequence[float], sample_time: float) -> List[float]:
        """Velocities from this observed sample and the last one, as the policy node estimates
        them behind a driver that reports none; zeros at the start of an episode."""
        positions = [float(value) for value in positions]
        if self._velocity_sample is None:
            velocities = [0.0] * len(positions)
        else:
            previous, previous_time, previous_velocities = self._velocity_sample
            elapsed = sample_time - previous_time
            velocities = [velocity_from_positions(now, before, elapsed, velocity)
                          for now, before, velocity in zip(positions, previous, previous_velocities)]
        self._velocity_sample = (positions, sample_time, velocities)
        return velocities

    @property
    def object_rest_z(self) -> float:
        """z (m, base_link) of the object's centre when it stands on the table."""
        return self._object_rest_z

    def _apply_randomisation(self, rng: np.random.Generator) -> None:
        """Object size/mass/friction, joint damping, latency, observation noise (if enabled)."""
        obj, rnd = self.cfg.object, self.cfg.randomisation
        on = rnd.enabled
        share = rnd.plain_episode_share
        if on and share > 0.0:  # drawn only when asked for: other configurations keep their episodes
            on = bool(rng.uniform() >= share)
        size = rng.uniform(*rnd.object_size_scale) if on else 1.0
        mass = obj.mass * (rng.uniform(*rnd.object_mass_scale) if on else 1.0)
        friction = obj.lateral_friction * (rng.uniform(*rnd.friction_scale) if on else 1.0)
        if obj.shape == "cylinder":
            dims = (obj.radius * size, obj.height * size)
        else:
            dims = (obj.half_extent * size,)
        self._object_rest_z = self.cfg.object_rest_z(size)
        self.world.set_object(obj.shape, dims, mass, friction)
        self._object_dims = dims
        self.robot.set_joint_damping(rng.uniform(*rnd.joint_damping) if on else 0.0)
        # The simulated position controller tracks differently at other physics steps: drawing
        # the step per episode keeps a policy from relying on one simulator's exact response.
        choices = rnd.physics_dt_choices
        physics_dt = float(rng.choice(choices)) if on and choices else self._physics_dt
        if physics_dt != self.world.physics_dt:
            self.world.set_physics_dt(physics_dt, self.control_dt)
        lo, hi = rnd.action_latency_steps
        self._latency_steps = int(rng.integers(lo, hi + 1)) if on else 0
        self._obs_noise_std = rnd.observation_noise_std if on else 0.0
        # Without timing_share, every perturbed episode has the in-period timing and every plain
        # one none: a policy then reads "no jitter" as "no latency" and rushes into whole-step
        # latency alone. Drawn only when asked for, so other configurations keep their episodes.
        timing = on
        timing_share = rnd.timing_share
        if on and timing_share < 1.0:
            timing = bool(rng.uniform() < timing_share)
        self._command_delay_range = tuple(rnd.command_delay_s) if timing else (0.0, 0.0)
        self._observation_age_range = tuple(rnd.observation_age_s) if timing else (0.0, 0.0)
        self._response = None
        if timing and any(tau > 0.0 for tau in rnd.response_time_constant_s):
            self._response = FirstOrderResponse(rnd.response_time_constant_s, physics_dt,
                                                self.robot_spec.home_joint_positions)
        self._period_timing = (self._command_delay_range[1] > 0.0 or self._observation_age_range[1] > 0.0
                               or self._response is not None)
        self._bridge = None
        if on and self._bridge_model is not None and rng.uniform() < rnd.gripper_bridge_share:
            timing = self._bridge_model.timing
            self._bridge = self._bridge_model
            self._bridge.reset(self.robot_spec.max_opening_width, float(rng.uniform(0.0, timing.call_period)),
                               float(rng.uniform(0.0, timing.read_period)), float(rng.uniform(0.0, timing.zero_debounce)))
        self._target = None
        if on and rnd.target_share > 0.0 and rng.uniform() < rnd.target_share:
            frame_period = 1.0 / rnd.target_rate_hz
            self._target = DelayedTarget(float(rng.uniform(*rnd.target_latency_s)), frame_period,
                                         float(rng.uniform(0.0, frame_period)))
            if rnd.target_action_latency_steps is not None:  # drawn only when set: configurations without it keep their episodes
                lo, hi = rnd.target_action_latency_steps
                self._latency_steps = int(rng.integers(lo, hi + 1))
        self._gripper_latency_steps = None
        if on and rnd.gripper_latency_steps is not None:  # drawn only when set: configurations without it keep their episodes
            lo, hi = rnd.gripper_latency_steps
            self._gripper_latency_steps = int(rng.integers(lo, hi + 1))
        # The policy node's motion guard, in plain episodes too (it runs on every chain): drawn
        # only when asked for, so that other configurations keep their episodes.
        self._guard_on = False
        if self._guard is not None and rng.uniform() < rnd.guard_share:
            self._guard_on = True
            self._guard.restart()
