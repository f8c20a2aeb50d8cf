"""One episode of a task on the simulated cell: the plant, the control chain, the draws and the task.

:class:`Episode` is what every stand-in for the arm shares: the gym environment
(:class:`fr5_rl.envs.FR5Env`) wraps it in gymnasium's API; the ROS simulator node, the replay
of a recording and the chain emulation drive its plant period by period (or physics step by
physics step) and let it judge. Only :mod:`fr5_rl.sim` talks to PyBullet.
"""
from __future__ import annotations

import copy
import dataclasses
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from .config import RobotSpec, load_robot_spec
from .control import JointCommandShaper, finite_values
from .control_chain import ControlChain
from .draws import EpisodeDraws, draw_episode, draw_place
from .env_config import EnvConfig, load_env_config
from .kinematics import ForwardKinematics
from .objects import ObjectShape, yaw_of
from .scenes import EpisodeScene
from .transforms import matrix_from_quaternion
from .observation import ActionHistory, ObservationBuilder, goal_features, object_features
from .sim.plant import JointStates, Measurement, Plant, Pose, SceneDescription
from .tasks import (TASKS, EpisodeVerdict, Task, TaskState, fingers_around_as_the_camera_sees,
                    held_as_the_camera_sees, task_state_from)


class Episode:
    """A task's episodes on one simulated cell, with the real chain's timing between policy and arm.

    :param task: a task's name (:data:`fr5_rl.tasks.TASKS`).
    :param cfg: the environment's configuration.
    :param robot: the arm (config/robots/<arm>.yaml).
    :param gui: PyBullet's window. :param renders: keep the renderer (pictures).
    """

    def __init__(self, task: str, cfg: EnvConfig, robot: RobotSpec, gui: bool = False, renders: bool = False) -> None:
        if task not in TASKS:
            raise ValueError(f"unknown task '{task}'; choose one of {sorted(TASKS)}")
        self.cfg, self.robot_spec = cfg, robot
        self.control_dt = cfg.simulation.control_dt
        self.task: Task = TASKS[task](cfg, robot.max_opening_width)
        self.kinematics = ForwardKinematics(robot)
        self.shaper = JointCommandShaper(robot, cfg.action, self.control_dt)
        self.observation_builder = ObservationBuilder(robot, cfg.observation, self.task.include_lift,
                                                      self.task.include_goal)
        self.action_history = ActionHistory(self.observation_builder.previous_actions)
        sim_cfg = cfg.simulation_for(task)
        self._physics_dt = sim_cfg.physics_dt
        self.plant = Plant(cfg, robot, sim_cfg, gui=gui, renders=renders)
        self.chain = ControlChain(cfg, robot, task, self.control_dt, self.shaper, self.kinematics,
                                  self.observation_builder.joint_step_hint is not None)
        self._workspace = (tuple(cfg.workspace.low), tuple(cfg.workspace.high))
        self.object_start: Tuple[float, float, float] = (0.0, 0.0, self.plant.object_rest_z)
        self.draws: Optional[EpisodeDraws] = None
        self.steps = 0  # control periods judged since the reset
        self.state: Optional[TaskState] = None  # the last one measured

    @classmethod
    def build(cls, task: str, robot: Optional[str] = None, overrides: Optional[Mapping[str, Any]] = None,
              gui: bool = False, renders: bool = False) -> "Episode":
        """An episode of ``task`` on ``robot`` (None: the configuration's arm), with ``overrides``
        merged into ``config/env.yaml`` as the gym environment takes them."""
        cfg = load_env_config({**(overrides or {}), **({"robot": robot} if robot is not None else {})})
        return cls(task, cfg, load_robot_spec(cfg.robot), gui=gui, renders=renders)

    def start(self, seed: int, options: Optional[Mapping[str, Any]] = None) -> Tuple[TaskState, np.ndarray]:
        """:meth:`reset` from ``seed``'s own generator: the episode gym's ``reset(seed=seed)`` makes
        (the same stream as gymnasium's seeding)."""
        return self.reset(np.random.default_rng(int(seed)), options)

    # ------------------------------------------------------------------ the episode's start
    def reset(self, rng: np.random.Generator, options: Optional[Mapping[str, Any]] = None) -> Tuple[TaskState, np.ndarray]:
        """A new episode: draw it, build the scene, stand the arm at its start.

        :param rng: the generator every draw comes from.
        :param options: ``object_xy`` (m, base_link) places the object there; ``arm_positions``
            (rad, j1 .. j6) keeps the arm there instead of a start drawn around home (the
            draws are made either way, so a seed places the same object); ``scene``
            (:class:`fr5_rl.scenes.EpisodeScene`): the object is that scene's target, with its goal,
            and its other objects stand around it (the other draws are made as ever).
        :return: the task's state and the policy's observation at the start.
        """
        options = options or {}
        scene: Optional[EpisodeScene] = options.get("scene")
        self.draws = draws = draw_episode(rng, self.cfg, self.robot_spec, self.task.name, self._physics_dt,
                                          self.chain.bridge_periods, self.chain.guard_available,
                                          options.get("object_xy") if scene is None else scene.target.position[:2])
        if scene is not None:
            self.draws = draws = scene.draws_for(draws)
        keep_arm = "arm_positions" in options
        start = (finite_values(options["arm_positions"], 6, "options['arm_positions']") if keep_arm
                 else draws.start_joint_positions)
        start = np.clip(start, self.robot_spec.lower_limits, self.robot_spec.upper_limits)
        self.object_start = self.plant.build_scene(draws, start, self.control_dt)
        self.plant.set_neighbours(() if scene is None else [
            (other.shape, other.mass, draws.object_friction, other.position, other.quaternion) for other in scene.others])
        if keep_arm and "object_xy" not in options and scene is None:
            self._place_clear_of_arm(rng)
        self.chain.begin(draws, start, self.plant.physics_dt, self.plant.substeps)
        for part in (self.shaper, self.action_history, self.task):
            part.reset()
        self.task.start(draws, self.plant.object_shape)
        self.steps = 0
        state, observation = self.observe(None, 0.0, rng)
        self.task.prime(state)
        return state, observation

    def _place_clear_of_arm(self, rng: np.random.Generator) -> None:
        """With the arm kept where it stands: draw the object's place again (after every other
        draw, so a seed whose object lies clear is placed as gym places it) while it would lie
        within ``object.placement_clearance`` of the arm or gripper.

        :raises RuntimeError: no clear place in ``object.placement_attempts`` draws (the arm
            covers the placement region: move it away first).
        """
        obj = self.cfg.object
        for _ in range(obj.placement_attempts):
            if not self.plant.object_near_arm(obj.placement_clearance):
                return
            self.object_start = self.plant.place_object(*draw_place(rng, self.cfg))
        if self.plant.object_near_arm(obj.placement_clearance):
            raise RuntimeError(f"no place for the object clear of the arm in {obj.placement_attempts} draws: "
                               "the arm covers the placement region; move it away before the reset")

    # ------------------------------------------------------------------ one period
    def act(self, action: Sequence[float], rng: np.random.Generator) -> Tuple[TaskState, np.ndarray]:
        """One control period from the policy's action through the chain and the plant.

        :param action: 7 finite floats, already clipped to [-1, 1].
        :return: the state at the period's end and the observation the policy gets.
        """
        if self.action_history.count:
            self.action_history.push(action)  # what the agent sent, before any delay
        targets, width = self.chain.command(action, self.steps * self.control_dt)
        early = self.chain.run_period(self.plant, targets, width, rng)
        return self.observe(early, (self.steps + 1) * self.control_dt, rng)

    def observe(self, early: Optional[Tuple[Measurement, float]] = None, now: float = 0.0,
                rng: Optional[np.random.Generator] = None) -> Tuple[TaskState, np.ndarray]:
        """The task's state now and the policy's observation through the chain.

        :param early: a joint state measured before the period's end, and how long before (s);
            None: measured now.
        :param now: s since the reset, the period's end.
        :param rng: the generator of the sensor noise (needed when the episode has noise).
        """
        measured = self.plant.measure()
        self.state = state = task_state_from(measured, self.plant.object_pose(), self.plant.contacts(),
                                             self.object_start, self._workspace)
        chain = self.chain
        reading, age, tcp_axis = (early[0], early[1], None) if early is not None else (measured, 0.0, state.tcp_approach_axis)
        # The detector's tracker judges the fingers by the gripper bridge's read-back, as the
        # policy does, where a bridge stands in between: not by the fingers themselves (a
        # read-back that lags a grasp leaves the object on the table for the tracker).
        tracked, read_back = state, None
        if chain.sees_through_camera and chain.bridge is not None:
            read_back = chain.bridge.observe(reading.gripper_width, now - age)
            tracked = dataclasses.replace(state, gripper_width=read_back)
        held = chain.sees_through_camera and self.held_as_the_camera_sees(tracked)
        around = held or (chain.sees_through_camera and self.cfg.randomisation.target_in_hand_from_grasp
                          and self.fingers_around_as_the_camera_sees(tracked))
        builder = self.observation_builder
        object_yaw = yaw_of(state.object_quaternion) if builder.object_features or builder.include_goal else 0.0
        sensed = chain.sense(reading, tcp_axis, state.object_position, state.tcp_to_object_distance, held,
                             now - age, now, rng, object_yaw, around, read_back)
        object_yaw = sensed.object_yaw
        shape = (object_features(self.plant.object_shape, object_yaw, yaw_of(reading.tcp_quaternion))
                 if builder.object_features else ())
        goal = (goal_features(self.plant.object_shape, sensed.object_position, object_yaw, self.draws.goal)
                if builder.include_goal else ())
        observation = builder.build_from(
            sensed.joint_positions, sensed.joint_velocities, sensed.gripper_width, self.chain.sent_gripper_width,
            sensed.tcp_position, sensed.tcp_approach_axis, sensed.object_position,
            sensed.object_position[2] - self.plant.object_rest_z, self.action_history.values(),
            tcp_jacobian=sensed.tcp_jacobian, object_features=shape, goal=goal,
        )
        return state, observation

    def judge_period(self, state: Optional[TaskState] = None) -> EpisodeVerdict:
        """Count and judge one control period: the task's success and failure tests, and the
        step limit (``"timeout"``). Stateful, like the task: call it exactly once per period.

        :param state: the state at the end of the period; None measures it now.
        """
        if state is None:
            self.state = state = self.task_state()
        self.steps = steps = self.steps + 1
        outcome = self.task.judge(state, self.control_dt)
        success, failure = outcome.success, outcome.failure
        terminated = success or failure is not None
        truncated = not terminated and steps >= self.task.max_steps
        return EpisodeVerdict(success, "timeout" if truncated else failure, terminated, truncated, steps, outcome)

    # ------------------------------------------------------------------ driving the plant directly
    def advance_physics(self, arm_targets: Sequence[float], gripper_width: float) -> None:
        """One physics step with the targets as they are (a real-time stand-in's own driver):
        no shaping or step limit, so the caller keeps them inside the joint limits. Call
        :meth:`judge_period` after every ``control_dt`` of simulated time.

        :param arm_targets: (6,) rad, j1 .. j6. :param gripper_width: m, 0 .. the maximum opening.
        """
        self.chain.advance_physics(self.plant, arm_targets, gripper_width)

    def advance_period(self, arm_targets: Sequence[float], gripper_width: float) -> None:
        """One control period with one command standing throughout (a lockstep driver), as
        the gym step does after shaping; then :meth:`judge_period`."""
        self.chain.advance_period(self.plant, arm_targets, gripper_width)

    def hold_object(self, object_in_tcp: Sequence[float]) -> None:
        """Fix the object in the gripper, its centre at ``object_in_tcp`` (m, tcp frame), as a
        person's hand-over leaves it (a camera calibration); :meth:`release_object` lets go."""
        self.plant.hold_object(object_in_tcp)

    def release_object(self) -> None:
        """Let go of an object held by :meth:`hold_object` (nothing if none is)."""
        self.plant.release_object()

    # ------------------------------------------------------------------ reads
    def task_state(self) -> TaskState:
        """Ground truth the task judges (four simulator queries)."""
        return task_state_from(self.plant.measure(), self.plant.object_pose(), self.plant.contacts(),
                               self.object_start, self._workspace)

    def fingers_around_as_the_camera_sees(self, state: TaskState) -> bool:
        """The fingers around the object as the detector's tracker decides it, lifted or not
        (:func:`fr5_rl.tasks.fingers_around_as_the_camera_sees`)."""
        shape = self.plant.object_shape
        return fingers_around_as_the_camera_sees(state, shape.grasp_width, self.cfg.randomisation, shape.size[2] / 2.0)

    def held_as_the_camera_sees(self, state: TaskState) -> bool:
        """The object is in the hand as the detector's tracker decides it
        (:func:`fr5_rl.tasks.held_as_the_camera_sees`)."""
        shape = self.plant.object_shape
        return held_as_the_camera_sees(state, shape.grasp_width, self.plant.object_rest_z, self.cfg.randomisation,
                                       shape.size[2] / 2.0)

    @property
    def gripper_command_width(self) -> float:
        """Opening width (m) the fingers were last commanded."""
        return self.chain.gripper_command_width

    @property
    def physics_dt(self) -> float:
        """s per physics step (drawn anew at every reset with ``randomisation.physics_dt_choices``)."""
        return self.plant.physics_dt

    def joint_positions(self) -> np.ndarray:
        """Measured arm joint angles (rad), controller order."""
        return self.plant.joint_positions()

    def tcp_position(self) -> np.ndarray:
        """tcp position (m, base_link), from the simulator."""
        return self.plant.tcp_position()

    def joint_states(self) -> JointStates:
        """All eight joints by name, for ``/joint_states``."""
        return self.plant.joint_states()

    def tcp_pose(self) -> Tuple[np.ndarray, np.ndarray]:
        """The tcp's position (m, base_link) and orientation (3x3 rotation, base_link) now."""
        measured = self.plant.measure()
        return (np.asarray(measured.tcp_position, dtype=np.float64),
                matrix_from_quaternion((0.0, 0.0, 0.0), measured.tcp_quaternion)[:3, :3])

    def object_pose(self) -> Pose:
        """The object's pose in base_link (ground truth)."""
        return self.plant.object_pose()

    def neighbour_poses(self) -> List[Pose]:
        """Where a scene's other objects are now (ground truth, base_link), in the scene's order."""
        return self.plant.neighbour_poses()

    def take_off_table(self, neighbours: Sequence[int], the_object: bool = False) -> None:
        """Take a scene's objects away between episodes (:meth:`fr5_rl.sim.plant.Plant.take_off_table`)."""
        self.plant.take_off_table(neighbours, the_object)

    def show_scene(self, bodies: Sequence[Tuple[ObjectShape, float, Sequence[float], Sequence[float]]]) -> None:
        """Between episodes: a new scene's objects (``(shape, mass, position, quaternion)``) stand
        on the table, the episode's own object set aside, until the next episode picks one."""
        friction = self.draws.object_friction if self.draws is not None else self.cfg.object.lateral_friction
        self.plant.set_neighbours([(shape, mass, friction, position, quaternion)
                                   for shape, mass, position, quaternion in bodies])
        if self.plant.object_shape is None and bodies:  # before any episode: an object to set aside
            shape, mass, position, _ = bodies[0]
            self.plant.set_object(shape.kind, shape.dims, mass, friction, float(position[2]))
        self.plant.take_off_table([], the_object=True)

    @property
    def neighbour_shapes(self) -> List[ObjectShape]:
        """A scene's other objects' kinds and sizes, in the scene's order."""
        return self.plant.neighbour_shapes

    def scene(self) -> SceneDescription:
        """The table, this episode's object and its goal (no simulator query)."""
        scene = self.plant.scene()
        goal = self.draws.goal if self.draws is not None else None
        return scene if goal is None else dataclasses.replace(scene, goal=tuple(goal))

    # ------------------------------------------------------------------ saved states
    def save_state(self) -> Dict[str, Any]:
        """The episode as it stands, for :meth:`restore_state` in the same episode's world."""
        return {"plant": self.plant.save_state(), "chain": self.chain.save_state(),
                "own": copy.deepcopy({"object_start": self.object_start, "draws": self.draws, "steps": self.steps,
                                      "state": self.state}),
                "parts": tuple(copy.deepcopy(part.__dict__) for part in (self.task, self.shaper, self.action_history))}

    def restore_state(self, saved: Dict[str, Any]) -> None:
        """Back to a state from :meth:`save_state` (it stays saved)."""
        self.plant.restore_state(saved["plant"])
        self.chain.restore_state(saved["chain"])
        self.__dict__.update(copy.deepcopy(saved["own"]))
        for part, state in zip((self.task, self.shaper, self.action_history), saved["parts"]):
            part.__dict__.update(copy.deepcopy(state))

    def discard_state(self, saved: Dict[str, Any]) -> None:
        """Free the simulator memory of a saved state."""
        self.plant.discard_state(saved["plant"])

    def close(self) -> None:
        """Disconnect from the simulator."""
        self.plant.close()


def placement_record(sim: Episode) -> Dict[str, Any]:
    """Where this episode's object started (``object_x``, ``object_y``: m, base_link) and what
    it is (``object``: :attr:`fr5_rl.objects.ObjectShape.label`): the fields a success map and
    a per-kind count read from an episode's record."""
    x, y = (round(float(value), 4) for value in sim.object_start[:2])
    return {"object_x": x, "object_y": y, "object": sim.scene().object_description.label}
