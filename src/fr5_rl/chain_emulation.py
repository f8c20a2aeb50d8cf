"""The rehearsal's chain in one process: the simulator, the drivers (the FAIRINO driver's servo
cycle, the gripper bridge calling the emulated controller) and the policy node's own code
(:class:`~fr5_rl.deploy.deployment.DeploymentStep`, :class:`~fr5_rl.deploy.joint_state.JointStateReader`),
physics step by physics step on one clock. ``tools/bench/timing.py`` runs it over hundreds of
episodes; the bench's docstring says what is emulated and how it compares with ROS.
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
from dataclasses import dataclass
from typing import Any, Dict, List, Mapping, Optional, Sequence

import numpy as np

from .config import load_yaml, package_root, typed, whole_multiple
from .deploy.bundle import deployment_overrides
from .deploy.deployment import Command, DeploymentStep, StepInputs
from .deploy.joint_state import FreshStateWait, JointStateReader, Reading, velocities_from_positions
from .drivers.gripper_bridge import GripperBridge, GripperReading
from .drivers.gripper_bridge_params import GripperBridgeParams
from .env_config import load_env_config
from .episode import Episode, placement_record
from .episode_runner import simulator_episode
from .motion_guard import load_guard_settings
from .objects import yaw_of
from .observation import DelayedTarget, tracker_hidden_timeout
from .sim.controller_emulator import ControllerEmulator
from .sim.gripper_chain import ChainClock, InProcessController
from .sim.node_params import SimNodeParams, load_sim_node_params
from .sim.servo import DriverModel

# m, tcp to cup centre: through the whole rehearsal (models/grasp, seeds 1020000-1020019) the
# detector's first "hidden" came at 0.075-0.141 m and 99 % of its "seen" frames at >= 0.179 m
# (docs/experiments.md, "The whole rehearsal: where the knock-overs come from").
CAMERA_HIDDEN_RADIUS_M = 0.15


def model_world(meta: Mapping[str, Any], params: SimNodeParams) -> Episode:
    """The world the simulator node builds for the model with ``meta`` (its ``meta.json``):
    the arm and objects the model was trained for, at the profile's physics step. Without the
    model's settings the world would hold only the default cup, whatever the model handles.
    """
    return simulator_episode(meta["task"], None, deployment_overrides(meta), params)


def simulator_profile(profile: str) -> SimNodeParams:
    """The simulator node's parameters for ``profile`` (``default`` or ``fairino``), as
    sim_policy.launch loads them."""
    return load_sim_node_params(profile)


@dataclass(frozen=True)
class Chain:
    """What stands between the policy and the arm.

    :param finger_source: ``driver`` (the arm's joint states carry the fingers) or ``bridge``
        (the gripper bridge's read-back of the emulated controller).
    :param velocity_source: ``driver`` (the messages' velocities) or ``positions`` (estimated).
    :param episode_start: ``reset`` (teleported to a start drawn around home) or ``go_to_start``.
    :param publish_velocities: the driver fills velocities (else 0.0, as the FAIRINO driver).
    :param target: ``simulator`` (the simulator's exact /target_pose) or ``camera`` (delayed as the
        camera and detector deliver it).
    """

    finger_source: str
    velocity_source: str
    episode_start: str
    publish_velocities: bool
    target: str = "simulator"

    @classmethod
    def of(cls, params: SimNodeParams, args: argparse.Namespace) -> "Chain":
        bridge = params.gripper_interface == "xmlrpc"
        velocity_source = args.velocity_source or ("driver" if params.publish_velocities else "positions")
        return cls(finger_source=args.finger_source or ("bridge" if bridge else "driver"),
                   velocity_source=velocity_source,
                   episode_start=args.episode_start or params.episode_start,
                   publish_velocities=velocity_source == "driver", target=args.target)


class ChainEmulation:
    """The simulator, the drivers and the policy node of one chain, on one clock."""

    def __init__(self, sim: Episode, step: DeploymentStep, chain: Chain, params: SimNodeParams,
                 compute_s: float, rng: np.random.Generator, trained_velocity_source: str,
                 hidden_radius: float = CAMERA_HIDDEN_RADIUS_M,
                 compute_samples_s: Optional[Sequence[float]] = None,
                 state_jitter_s: float = 0.0, fresh_state_wait_s: float = 0.0, fresh_state_max_age_s: float = 0.0,
                 policy_phase_s: Optional[float] = None, drop_hidden: bool = True) -> None:
        self.sim, self.step, self.chain, self.rng = sim, step, chain, rng
        self.robot = sim.robot_spec
        self.physics_dt = params.physics_dt
        self.per_period = whole_multiple(sim.control_dt, self.physics_dt)
        self.per_publish = whole_multiple(1.0 / params.publish_rate, self.physics_dt)
        self.driver = DriverModel(params.servo_rate, params.servo_delay_cycles,
                                  params.response_time_constant_s, self.physics_dt,
                                  sim.joint_positions())
        self.compute_steps = int(round(compute_s / self.physics_dt))
        # Measured compute latencies (s) to draw each period's from, instead of the fixed one.
        self.compute_samples = None if compute_samples_s is None else np.asarray(compute_samples_s, dtype=float)
        self.pause_steps = int(round(params.pause_between_episodes / self.physics_dt))
        # Each joint state reaches the node up to this much after it was sampled (a late simulator
        # loop, the transport): near the timer's ticks, some periods then find no new state.
        self.state_jitter_s = state_jitter_s
        self.fresh_state = FreshStateWait(fresh_state_wait_s, fresh_state_max_age_s)  # as policy_node
        # The phase of the node's ticks after the driver's joint-state publishing, the same in every
        # episode (a launch's: the rehearsal keeps one for its 20); None: drawn per episode.
        self.policy_phase_steps: Optional[int] = None
        if policy_phase_s is not None:
            steps = 0 if policy_phase_s == 0 else whole_multiple(policy_phase_s, self.physics_dt)
            if steps is None or steps >= self.per_period:
                raise ValueError(f"policy phase {policy_phase_s * 1000:g} ms: a whole number of physics steps "
                                 f"({self.physics_dt * 1000:g} ms) below the control period, please")
            self.policy_phase_steps = steps
        self.wait_steps = int(fresh_state_wait_s / self.physics_dt + 1e-9)
        self.in_flight: List[tuple] = []  # (physics step it reaches the node, names, positions, velocities, stamp)
        self.repeated_states = self.periods = 0
        guard = load_guard_settings()
        estimate = velocities_from_positions("positions" if chain.velocity_source == "positions" else "driver",
                                             trained_velocity_source)
        self.reader = JointStateReader(self.robot.joint_names, self.robot.finger_joint_names,
                                       velocities_from_positions=estimate,
                                       max_joint_speeds=self.robot.velocity_limits * guard.glitch_speed_factor,
                                       estimate_interval=0.9 * sim.control_dt)  # as policy_node
        self.clock = ChainClock()
        self.fault: Optional[str] = None
        self.emulator: Optional[ControllerEmulator] = None
        self.bridge: Optional[GripperBridge] = None
        if chain.finger_source == "bridge":
            self._start_bridge(params)
        self.previous_end: Optional[List[float]] = None
        camera = load_env_config().randomisation  # the measured camera timing (config/sim.yaml)
        self.target_latency_s, self.target_period_s = tuple(camera.target_latency_s), 1.0 / camera.target_rate_hz
        self.hidden_radius = hidden_radius
        # The camera's target dropped as the detector's tracker drops an object hidden too long
        # (drop_hidden; False: believed where it was last seen however long it stays hidden).
        self.hidden_timeout = tracker_hidden_timeout() if drop_hidden else None

    def _start_bridge(self, params: SimNodeParams) -> None:
        self.emulator = ControllerEmulator(params.controller_emulator, 0, self.clock)  # never started: no socket
        bridge_params = typed(GripperBridgeParams, load_yaml(package_root() / "config" / "gripper_bridge.yaml"),
                              "config/gripper_bridge.yaml")
        finger_names = list(self.robot.finger_joint_names)

        def on_reading(reading: GripperReading) -> None:  # gripper_bridge_node.publish_fingers
            half = 0.5 * reading.width
            self.reader.update(finger_names, [half] * len(finger_names), [], self.clock.now, self.clock.now)

        def on_fault(fault: bool) -> None:
            self.fault = "the gripper bridge reports a fault" if fault else None

        self.bridge = GripperBridge(bridge_params, self.robot.max_opening_width, report=lambda level, text: None,
                                    client=InProcessController(self.emulator), clock=self.clock,
                                    on_reading=on_reading, on_fault=on_fault)
        self.emulator.set_measured_width(self.robot.max_opening_width, moving=False)
        # The node publishes the fault true at start (latched) and the policy node holds on it.
        self.fault = "the gripper bridge reports a fault"
        # Reset, activation and their settle times, before the first episode (the launch's start-up,
        # during which the policy node holds on the fault): until the gripper can act.
        self.bridge.submit(self.robot.max_opening_width)
        for _ in range(int(10.0 / self.physics_dt)):
            self.clock.now += self.physics_dt
            self._poll_bridge()
            if self.fault is None and self.bridge.status().measured_width is not None:
                break
        else:
            raise RuntimeError(f"the emulated gripper bridge was not ready within 10 s: {self.bridge.status()}")

    def _poll_bridge(self) -> None:
        for _ in range(10):
            if self.bridge.poll() is None:
                return

    def _publish_joint_states(self, k: int) -> None:
        """Sample the driver's joint state at physics step ``k``; it reaches the node at once, or
        a drawn delivery delay later (``state_jitter_s``)."""
        states = self.sim.joint_states()
        arm = len(self.robot.joint_names)
        count = len(states.names) if self.chain.finger_source == "driver" else arm
        velocities = states.velocities[:count] if self.chain.publish_velocities else [0.0] * count
        delay_steps = 0
        if self.state_jitter_s > 0.0:
            delay_steps = int(np.ceil(self.rng.uniform(0.0, self.state_jitter_s) / self.physics_dt - 1e-9))
        self.in_flight.append((k + delay_steps, states.names[:count], states.positions[:count], velocities,
                               self.clock.now))

    def _deliver_joint_states(self, k: int) -> None:
        """The states that reach the node by physics step ``k``, oldest first."""
        while self.in_flight and self.in_flight[0][0] <= k:
            _, names, positions, velocities, stamp = self.in_flight.pop(0)
            self.reader.update(names, positions, velocities, stamp, self.clock.now)

    def _follow_controller(self) -> float:
        """sim_node._follow_controller: the fingers take the emulated controller's width."""
        states = self.sim.joint_states()
        arm = len(self.robot.joint_names)
        self.emulator.set_measured_width(sum(states.positions[arm:]),
                                         moving=any(abs(speed) > 1e-3 for speed in states.velocities[arm:]))
        width = self.emulator.commanded_width()
        return self.robot.max_opening_width if width is None else float(np.clip(width, 0.0, self.robot.max_opening_width))

    def run_episode(self, seed: int) -> Dict[str, Any]:
        """One episode as the real-time simulator runs it; its outcome and length in periods."""
        sim, step = self.sim, self.step
        teleported = not (self.chain.episode_start == "go_to_start" and self.previous_end is not None)
        if teleported:
            sim.start(seed)
        else:
            sim.start(seed, options={"arm_positions": self.previous_end})
        scene = sim.scene()
        self._deliver_joint_states(sys.maxsize)  # the pause between episodes outlasts any delivery delay
        if teleported:
            # The simulator node pauses the policy node over a teleport and resumes it (~enable
            # true) once the new state has reached it: the jump is accepted, not latched.
            self._publish_joint_states(0)
            self._deliver_joint_states(sys.maxsize)
            self.reader.accept_current()
        # A driver's servo loop runs on across episodes, as the simulator node's does.
        self.driver.reset(sim.joint_positions(), restart_cycle=False)
        step.start_episode()
        self.reader.restart_estimates()  # policy_node.on_reset
        positioning = self.chain.episode_start == "go_to_start"
        publish_phase, policy_phase = int(self.rng.integers(self.per_publish)), int(self.rng.integers(self.per_period))
        if self.policy_phase_steps is not None:  # the node's ticks this long after the driver's publishing
            publish_phase, policy_phase = 0, (-self.policy_phase_steps) % self.per_period
        camera, episode_start_s = None, self.clock.now
        if self.chain.target == "camera":
            # Held where the tracker puts it, not the truth; dropped, as the tracker drops it, once
            # hidden for longer than its hidden_timeout (the node then finds its target stale).
            camera = DelayedTarget(float(self.rng.uniform(*self.target_latency_s)), self.target_period_s,
                                   float(self.rng.uniform(0.0, self.target_period_s)),
                                   hand_from_grasp=True, hidden_timeout=self.hidden_timeout)
        arm_command: Optional[Sequence[float]] = None
        gripper_width = self.robot.max_opening_width
        pending: List[tuple] = []  # (physics step it arrives at, arm targets, gripper width, from the policy)
        first_command_step: Optional[int] = None
        start_move_s = 0.0
        waiting_until: Optional[int] = None  # a period waiting for a new state, until this step at most
        k = 0
        while True:
            self.clock.now += self.physics_dt
            if (k + publish_phase) % self.per_publish == 0:
                self._publish_joint_states(k)
            self._deliver_joint_states(k)
            if self.bridge is not None:
                self._poll_bridge()
                gripper_width = self._follow_controller()
            if (k + policy_phase) % self.per_period == 0:
                waiting_until = k + self.wait_steps
            reading = self.reader.reading() if waiting_until is not None else None
            if waiting_until is not None and (self.fresh_state.is_new(reading, self.clock.now) or k >= waiting_until):
                waiting_until = None
                self.periods += 1
                self.repeated_states += not self.fresh_state.is_new(reading)
                self.fresh_state.used(reading)
                now = self.clock.now
                target = self._target(camera, now - episode_start_s)
                # The object's shape and the goal, as the simulator node publishes them (latched,
                # before the episode's first period).
                shape = Reading(scene.object_description, now, stamp=now)
                goal = None if scene.goal is None else Reading(tuple(scene.goal), now, stamp=now)
                result = step(StepInputs(now, reading, target, now, self.fault, object_shape=shape, goal=goal))
                if isinstance(result, Command):
                    pending.append((k + self._compute_steps(), result.arm_positions, result.gripper_width,
                                    result.target_in_base is not None))
            while pending and pending[0][0] <= k:
                _, arm_command, width, from_policy = pending.pop(0)
                if self.bridge is not None:
                    self.bridge.submit(width)
                else:
                    gripper_width = width
                if positioning and from_policy:
                    positioning, start_move_s = False, k * self.physics_dt
                if first_command_step is None and not positioning:
                    first_command_step = k
            sim.advance_physics(self.driver.targets_for_step(arm_command), gripper_width)
            k += 1
            if first_command_step is not None and (k - first_command_step) % self.per_period == 0:
                verdict_now = sim.judge_period()
                if verdict_now.ended:
                    self._pause(arm_command)
                    self.previous_end = sim.joint_positions().tolist()
                    return {"seed": seed, **placement_record(sim), "success": bool(verdict_now.success),
                            "failure": verdict_now.failure,
                            "steps": (k - first_command_step) // self.per_period, "start_move_s": round(start_move_s, 3)}
            if k * self.physics_dt > 120.0:
                raise RuntimeError(f"seed {seed}: no verdict after 120 s of simulated time (start move stuck?)")

    def _compute_steps(self) -> int:
        """Physics steps from the period's start to the command acting: fixed, or drawn from
        the measured latencies."""
        if self.compute_samples is None:
            return self.compute_steps
        return int(round(float(self.rng.choice(self.compute_samples)) / self.physics_dt))

    def _target(self, camera: Optional[DelayedTarget], since_start_s: float) -> Reading:
        """The target the node has at this period: the simulator's, or the camera's (stamped
        with its capture time, in the base frame as the node's tf gives it)."""
        now = self.clock.now
        pose = self.sim.object_pose()
        # The yaw travels with the position through the camera's timing (held while hidden, as
        # the tracker holds it; in the hand the true yaw, as the tracker's pads squaring a box give
        # it, and the position fixed in the tcp frame from the grasp, as the tracker computes it).
        yaw = yaw_of(pose.quaternion)
        if camera is None:
            return Reading((*pose.position, yaw), now, stamp=now)
        state = self.sim.task_state()
        if self.bridge is not None and self.bridge.measured is not None:
            # The detector's tracker judges the fingers by the bridge's read-back (the finger joint
            # states it publishes), not by the fingers themselves: a read-back that lags a grasp
            # leaves the object on the table for the tracker (the rehearsal's place timeouts, stop 65).
            state = dataclasses.replace(state, gripper_width=self.bridge.measured.width)
        held = self.sim.held_as_the_camera_sees(state)
        around = held or self.sim.fingers_around_as_the_camera_sees(state)
        tcp = self.sim.tcp_pose() if around else None
        position = camera.observe((*state.object_position, yaw), since_start_s, held,
                                  state.tcp_to_object_distance <= self.hidden_radius, tcp, around)
        return Reading(tuple(position), now, stamp=now - since_start_s + camera.seen_at)

    def _pause(self, arm_command: Optional[Sequence[float]]) -> None:
        """The simulator's pause between episodes: the arm holds where it ended, the fingers as commanded."""
        hold = tuple(self.sim.joint_positions())
        for _ in range(self.pause_steps):
            self.clock.now += self.physics_dt
            width = self.robot.max_opening_width
            if self.bridge is not None:
                self._poll_bridge()
                width = self._follow_controller()
            self.sim.advance_physics(hold, width)
