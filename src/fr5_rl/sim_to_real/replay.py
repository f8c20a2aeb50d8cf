"""Replay a recorded run's commands in the simulator, behind a driver profile.

The simulated arm starts where the recorded one was, gets every recorded command at the time it
was received, through the profile's servo cycle and response exactly as the simulator node
passes them on (:class:`~fr5_rl.sim.servo.DriverModel`: the servo cycle, then the response),
and its joint positions are taken at the recorded joint states' stamps. Where the recorded arm
jumps (the simulator's teleporting reset between episodes; a real arm never does), the replay
starts again from the recorded state.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from ..config import DEFAULT_ROBOT, whole_multiple
from ..episode import Episode
from ..sim.driver_profile import DriverProfile
from ..sim.node_params import load_sim_node_params
from ..sim.servo import DriverModel
from .recording import RunRecording


@dataclass
class Replay:
    """What the simulated arm did.

    :param positions: (n, 6) rad at the recording's joint state stamps.
    :param segments: (start, end) indices into the joint states of each stretch replayed
        without a restart.
    """

    positions: np.ndarray
    segments: List[Tuple[int, int]]


def replay_segments(recording: RunRecording, velocity_limits: Sequence[float], margin: float = 2.0,
                    slack: float = 0.01, pause_margin: float = 0.1, rest_speed: float = 0.01) -> List[Tuple[int, int]]:
    """The stretches of a run that a driver produced from its commands: split where the arm
    moved faster than its joints can (``margin`` times the limit, plus ``slack`` rad: a reset
    placed it), and without the recorded pauses (plus ``pause_margin`` s after each), in which
    the rehearsal's arm ignored its commands. Each starts after the first recorded command, with
    the arm at rest (fastest joint under ``rest_speed`` rad/s) if it comes to rest at all.

    :return: (start, end) joint state indices, end exclusive.
    """
    times, positions = recording.state_times, recording.positions
    limits = np.asarray(velocity_limits, dtype=float)
    jumps = np.abs(np.diff(positions, axis=0)) > margin * limits * np.diff(times)[:, None] + slack
    usable = np.ones(len(times), dtype=bool)
    for start, end in recording.pauses:
        usable &= ~((times >= start) & (times <= end + pause_margin))
    breaks = np.zeros(len(times), dtype=bool)
    breaks[1:] = jumps.any(axis=1) | ~usable[:-1]
    segments, start = [], None
    for index in range(len(times)):
        if not usable[index]:
            start = None
            continue
        if start is None or breaks[index]:
            if start is not None:
                segments.append((start, index))
            start = index
        if index == len(times) - 1 or not usable[index + 1]:
            segments.append((start, index + 1))
            start = None
    # A stretch starts where the replay knows how the arm got there: after the first recorded
    # command (a recorder that subscribed late misses the first ones), and at rest (the replay
    # starts its arm at rest where the recorded one is).
    first_command = recording.command_times[0] if len(recording.command_times) else np.inf
    speeds = np.zeros(len(times))  # towards the next state: a reset's jump is not the new stretch's speed
    if len(times) > 1:
        speeds[:-1] = (np.abs(np.diff(positions, axis=0)) / np.maximum(np.diff(times), 1e-9)[:, None]).max(axis=1)
    trimmed = []
    for start, end in segments:
        while start < end and times[start] < first_command:
            start += 1
        resting = [index for index in range(start, end) if speeds[index] < rest_speed]
        if resting and speeds[start] >= rest_speed:
            start = resting[0]
        trimmed.append((start, end))
    return [(a, b) for a, b in trimmed if b - a >= 2]


class Replayer:
    """One simulated world that replays runs (reused across profiles: building it costs more
    than a short replay).

    :param task: the environment whose scene the arm moves in (reach | grasp).
    :param physics_dt: s, the physics step (the profile's).
    :param robot: the arm that made the run (``config/robots/``).
    """

    def __init__(self, task: str, physics_dt: float, robot: str = DEFAULT_ROBOT) -> None:
        solver_iterations = load_sim_node_params().solver_iterations
        self.physics_dt = float(physics_dt)
        self.sim = Episode.build(task, robot, {task: {"simulation": {
            "physics_dt": self.physics_dt, "solver_iterations": solver_iterations}}})
        self.spec = self.sim.robot_spec

    def close(self) -> None:
        self.sim.close()

    def run(self, recording: RunRecording, profile: DriverProfile, phase_steps: int = 0,
            response: Optional[Sequence[float]] = None) -> Replay:
        """Replay ``recording`` behind ``profile``.

        :param phase_steps: physics steps of the servo cycle already done at the first joint
            state (where its boundaries fall against the stamps; a fit tries each).
        :param response: time constants (s) instead of the profile's.
        :raises ValueError: the profile's physics step is not this replayer's.
        """
        if abs(profile.physics_dt - self.physics_dt) > 1e-12:
            raise ValueError(f"the profile's physics_dt {profile.physics_dt} s is not the replayer's {self.physics_dt} s")
        dt = self.physics_dt
        taus = list(profile.response_time_constant_s if response is None else response) or [0.0] * 6
        out = np.zeros_like(recording.positions)
        segments = replay_segments(recording, self.spec.velocity_limits)
        commands, command_times = recording.commands, recording.command_times
        for start, end in segments:
            t0 = recording.state_times[start]
            first = recording.positions[start]
            self.sim.start(0, options={"arm_positions": first.tolist()})
            driver = DriverModel(profile.servo_rate, profile.servo_delay_cycles, taus, dt, first)
            driver.reset(first, phase_steps=phase_steps)
            sample_steps = np.rint((recording.state_times[start:end] - t0) / dt).astype(int)
            # Commands received before the segment's first step stand (the newest of them).
            pointer = int(np.searchsorted(command_times, t0, side="right"))
            newest: Optional[Tuple[float, ...]] = tuple(commands[pointer - 1]) if pointer > 0 else None
            gripper_pointer = int(np.searchsorted(recording.gripper_times, t0, side="right"))
            width = (float(recording.gripper_widths[gripper_pointer - 1]) if gripper_pointer > 0
                     else self.spec.max_opening_width)
            total = int(sample_steps[-1])
            sample_index = 1
            out[start] = first
            for step in range(total):
                now = t0 + step * dt
                while pointer < len(command_times) and command_times[pointer] <= now:
                    newest = tuple(commands[pointer])
                    pointer += 1
                while (gripper_pointer < len(recording.gripper_times)
                       and recording.gripper_times[gripper_pointer] <= now):
                    width = float(recording.gripper_widths[gripper_pointer])
                    gripper_pointer += 1
                self.sim.advance_physics(driver.targets_for_step(newest), width)
                done = step + 1
                while sample_index < len(sample_steps) and sample_steps[sample_index] <= done:
                    out[start + sample_index] = self.sim.joint_positions()
                    sample_index += 1
        return Replay(out, segments)


def tracking_errors(recording: RunRecording, replay: Replay) -> np.ndarray:
    """(n, 6) rad, simulated minus recorded position at every replayed joint state (the first of
    each segment, where both start, included)."""
    mask = np.zeros(len(recording.state_times), dtype=bool)
    for start, end in replay.segments:
        mask[start:end] = True
    return (replay.positions - recording.positions)[mask]


def summary(errors: np.ndarray, joint_names: Sequence[str]) -> Dict[str, Any]:
    """RMS and max absolute error per joint and over all (rad and deg)."""
    rms = np.sqrt(np.mean(errors ** 2, axis=0)) if len(errors) else np.zeros(len(joint_names))
    largest = np.max(np.abs(errors), axis=0) if len(errors) else np.zeros(len(joint_names))
    return {
        "rms_rad": float(np.sqrt(np.mean(errors ** 2))) if len(errors) else 0.0,
        "max_rad": float(np.max(np.abs(errors))) if len(errors) else 0.0,
        "per_joint": {name: {"rms_rad": float(r), "max_rad": float(m), "rms_deg": float(np.degrees(r)),
                             "max_deg": float(np.degrees(m))} for name, r, m in zip(joint_names, rms, largest)},
    }


def replay_error(recording: RunRecording, profile: DriverProfile, task: str = "reach",
                 phases: Optional[Sequence[int]] = None, robot: str = DEFAULT_ROBOT) -> Dict[str, Any]:
    """A profile's replay error on a run, at the servo phase that fits best (the recording does
    not say where the driver's cycle boundaries fell).

    :param robot: the arm that made the run.

    :return: :func:`summary` plus ``phase_steps`` and the replay.
    """
    steps_per_cycle = (whole_multiple(profile.servo_period, profile.physics_dt) or 1) if profile.servo_rate > 0 else 1
    replayer = Replayer(task, profile.physics_dt, robot)
    best: Optional[Dict[str, Any]] = None
    try:
        for phase in (phases if phases is not None else range(steps_per_cycle)):
            replay = replayer.run(recording, profile, phase_steps=phase)
            report = summary(tracking_errors(recording, replay), recording.joint_names)
            if best is None or report["rms_rad"] < best["rms_rad"]:
                best = {**report, "phase_steps": phase, "replay": replay}
    finally:
        replayer.close()
    return best
