"""Fit a driver profile to a recorded run: servo rate, delay cycles, and each joint's response.

The servo cycle is discrete (a rate, whole cycles of delay, where the cycle's boundaries fall
against the stamps): every candidate is tried. For each, the response (a first-order lag per
joint) is searched by replaying the run in the simulator exactly as the simulator node would run
that profile (:class:`~fr5_rl.sim_to_real.replay.Replayer`): filtering the replayed motion
afterwards instead would be cheaper, but the simulated position controller saturates its
velocity and force on the unfiltered targets, so the two do not commute and the cheap way picks
the wrong delay. The candidate whose best response replays the run most closely wins.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional

import numpy as np

from ..config import DEFAULT_ROBOT, load_yaml, typed, whole_multiple
from ..sim.driver_profile import DriverProfile
from .recording import RecordingError, RunRecording
from .replay import Replay, Replayer, summary, tracking_errors


@dataclass(frozen=True)
class FitSettings:
    """``config/sim_to_real.yaml``'s ``fit`` section.

    :param servo_rates: Hz, more servo rates to try beside the base profile's (those whose period
        is not a whole number of physics steps are skipped). Empty: the base profile's only. A
        driver's loop rate is a setting one can read (the vendor's ``loop_hz``), and a rate and
        a delay trade off (250 Hz x 4 cycles against 125 Hz x 2) within what 50 Hz joint states
        can tell apart on a loaded machine.
    :param max_delay_cycles: delays 0 .. this many cycles are tried.
    :param max_time_constant_s: the largest time constant searched (s).
    :param time_constant_tolerance_s: the search stops when each joint's is known this well (s).
    :param min_moving_s: s of arm motion a run needs for a fit.
    :param max_replay_s: s of the run used (its start); longer runs are cut.
    :param loss: how a replay's error is scored: ``mae`` (mean absolute; a few commands
        delivered late on a loaded machine make spikes that squared error over-weights) or ``mse``.
    """

    servo_rates: List[float] = field(default_factory=list)
    max_delay_cycles: int = 4
    max_time_constant_s: float = 0.3
    time_constant_tolerance_s: float = 0.002
    loss: str = "mae"
    min_moving_s: float = 10.0
    max_replay_s: float = 60.0


@dataclass(frozen=True)
class SimToRealSettings:
    """``config/sim_to_real.yaml``: what a comparison and a fit run against.

    :param base_profile: the driver profile a recording is compared with and a fit starts from
        (``config/<base_profile>.yaml``).
    :param task: the environment whose scene the replayed arm moves in (reach | grasp).
    :param fit: the fit's search (:class:`FitSettings`).
    """

    base_profile: str
    task: str
    fit: FitSettings


def load_sim_to_real_settings() -> SimToRealSettings:
    """``config/sim_to_real.yaml``, typed (unknown or missing keys are refused)."""
    return typed(SimToRealSettings, load_yaml("sim_to_real"), "config/sim_to_real.yaml")


@dataclass
class FitResult:
    """What the fit found.

    :param profile: the fitted profile (the base profile's other keys kept).
    :param phase_steps: where the servo cycle's boundaries fell against the stamps (physics steps).
    :param rms_rad: replay error of the fitted profile (the lag before the controller), rad.
    :param candidates: every candidate tried: rate, delay, phase, and its error after the
        response fit (rad), best first.
    :param per_joint: the fitted profile's replay error per joint.
    """

    profile: DriverProfile
    phase_steps: int
    rms_rad: float
    candidates: List[Dict[str, Any]]
    per_joint: Dict[str, Any]


def check_fittable(recording: RunRecording, settings: FitSettings) -> None:
    """Refuse a run too short to fit.

    :raises RecordingError: with how much more motion is needed.
    """
    moving = recording.moving_time()
    if moving < settings.min_moving_s:
        raise RecordingError(f"{recording.source}: the arm moved for {moving:.1f} s; a fit needs "
                             f"{settings.min_moving_s:g} s of motion: record {settings.min_moving_s - moving:.1f} s more")
    if len(recording.command_times) < 10:
        raise RecordingError(f"{recording.source}: {len(recording.command_times)} commands; a fit needs the arm "
                             "moving on its commands (record while the policy node is enabled)")


GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0


def per_joint_errors(recording: RunRecording, replay: Replay, loss: str = "mse") -> np.ndarray:
    """(6,) replay error per joint: mean squared (rad^2, ``mse``) or mean absolute (rad, ``mae``)."""
    errors = tracking_errors(recording, replay)
    if not len(errors):
        return np.zeros(recording.positions.shape[1])
    return np.mean(np.abs(errors), axis=0) if loss == "mae" else np.mean(errors ** 2, axis=0)


def fit_response(replayer: Replayer, recording: RunRecording, candidate: DriverProfile, phase: int,
                 settings: FitSettings) -> np.ndarray:
    """Each joint's time constant (s) for one servo candidate, by replaying it: a golden-section
    search per joint, all joints at once (one replay per iteration gives every joint's error, and
    a joint's error hardly depends on the others' lag).

    :return: (6,) s, each within ``settings.time_constant_tolerance_s`` of its best.
    """
    def errors(taus: np.ndarray) -> np.ndarray:
        return per_joint_errors(recording, replayer.run(recording, candidate, phase, response=taus), settings.loss)

    n = recording.positions.shape[1]
    low, high = np.zeros(n), np.full(n, settings.max_time_constant_s)
    inner_low, inner_high = high - GOLDEN * (high - low), low + GOLDEN * (high - low)
    error_low, error_high = errors(inner_low), errors(inner_high)
    while float(np.max(high - low)) > settings.time_constant_tolerance_s:
        left = error_low < error_high  # per joint: the best lies in [low, inner_high], else [inner_low, high]
        high, low = np.where(left, inner_high, high), np.where(left, low, inner_low)
        kept, kept_error = np.where(left, inner_low, inner_high), np.where(left, error_low, error_high)
        probe = np.where(left, high - GOLDEN * (high - low), low + GOLDEN * (high - low))
        probe_error = errors(probe)
        inner_low, error_low = np.where(left, probe, kept), np.where(left, probe_error, kept_error)
        inner_high, error_high = np.where(left, kept, probe), np.where(left, kept_error, probe_error)
    return np.where(error_low < error_high, inner_low, inner_high)


def fit_driver(recording: RunRecording, base: DriverProfile, settings: FitSettings, task: str = "reach",
               progress: Optional[Any] = None, robot: str = DEFAULT_ROBOT) -> FitResult:
    """Fit ``base``'s driver model to ``recording``.

    :param base: the profile whose other keys (topics, physics step, state rate) the fitted one
        keeps.
    :param progress: called with a line per candidate, if given.
    :param robot: the arm that made the run (``config/robots/``).
    :raises RecordingError: the run is too short (:func:`check_fittable`).
    """
    check_fittable(recording, settings)
    start = recording.state_times[0]
    recording = recording.window(start, start + settings.max_replay_s)
    dt = base.physics_dt
    rates = sorted({float(rate) for rate in [base.servo_rate, *settings.servo_rates]
                    if rate > 0 and rate * dt <= 1.0 + 1e-9 and whole_multiple(1.0 / rate, dt) is not None})
    replayer = Replayer(task, dt, robot)
    candidates: List[Dict[str, Any]] = []
    try:
        for rate in rates:
            steps_per_cycle = whole_multiple(1.0 / rate, dt) or 1
            for delay in range(settings.max_delay_cycles + 1):
                for phase in range(steps_per_cycle):
                    candidate = base.with_model(rate, delay, [])
                    taus = fit_response(replayer, recording, candidate, phase, settings)
                    replay = replayer.run(recording, candidate, phase_steps=phase, response=taus)
                    errors = tracking_errors(recording, replay)
                    rms = math.sqrt(float(np.mean(errors ** 2)))
                    score = rms if settings.loss == "mse" else float(np.mean(np.abs(errors)))
                    candidates.append({"servo_rate": rate, "servo_delay_cycles": delay, "phase_steps": phase,
                                       "rms_rad": rms, "score": score, "response_time_constant_s": [round(t, 5) for t in taus]})
                    if progress is not None:
                        progress(f"  {rate:g} Hz, {delay} cycles, phase {phase}: {math.degrees(rms):.4f} deg RMS, "
                                 f"{math.degrees(score):.4f} deg {settings.loss}")
        candidates.sort(key=lambda entry: entry["score"])
        best = candidates[0]
        profile = base.with_model(best["servo_rate"], best["servo_delay_cycles"], best["response_time_constant_s"])
        replay = replayer.run(recording, profile, phase_steps=best["phase_steps"])
        errors = tracking_errors(recording, replay)
        report = summary(errors, recording.joint_names)
    finally:
        replayer.close()
    return FitResult(profile, int(best["phase_steps"]), report["rms_rad"], candidates, report["per_joint"])
