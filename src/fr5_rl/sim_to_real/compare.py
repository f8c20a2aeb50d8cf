"""Measures of the gap between a recorded arm and its replay: tracking error, delay, limits."""
from __future__ import annotations

from pathlib import Path
from typing import Any, Dict, Optional, Sequence

import numpy as np

from ..config import RobotSpec
from .recording import RunRecording
from .replay import Replay


def commands_at(times: np.ndarray, command_times: np.ndarray, commands: np.ndarray) -> np.ndarray:
    """(n, 6) the newest command received at or before each time (the first one before any)."""
    index = np.searchsorted(command_times, times, side="right") - 1
    return commands[np.clip(index, 0, len(commands) - 1)]


def estimated_delay(times: np.ndarray, positions: np.ndarray, command_times: np.ndarray, commands: np.ndarray,
                    moving: np.ndarray, most: float = 0.3, step: float = 0.002) -> float:
    """s by which the arm follows its commands: the shift of the command stream that best
    matches the measured positions (least squares over the moving samples). It counts every
    cause alike: the servo cycle's wait and delay, the response's lag, transport.

    :param moving: (n,) which samples to use (the arm moving).
    """
    if not moving.any() or len(commands) == 0:
        return float("nan")
    shifts = np.arange(0.0, most + 1e-12, step)
    errors = [float(np.mean((commands_at(times[moving] - shift, command_times, commands) - positions[moving]) ** 2))
              for shift in shifts]
    return float(shifts[int(np.argmin(errors))])


def moving_samples(recording: RunRecording, speed_threshold: float = 0.05) -> np.ndarray:
    """(n,) joint states at which some joint moves faster than ``speed_threshold`` (rad/s)."""
    moving = np.zeros(len(recording.state_times), dtype=bool)
    if len(moving) > 1:
        speed = np.abs(np.diff(recording.positions, axis=0)) / np.maximum(np.diff(recording.state_times), 1e-9)[:, None]
        moving[1:] = (speed > speed_threshold).any(axis=1)
    return moving


def limit_hits(recording: RunRecording, spec: RobotSpec, position_margin: float = 1e-3,
               velocity_margin: float = 1.001) -> Dict[str, float]:
    """Share of the commands at a joint limit (within ``position_margin`` rad) or asking for
    more than a joint's velocity limit since the previous command (``velocity_margin`` times).
    A policy that lives at its limits behaves differently where the arm's limits differ."""
    commands, times = recording.commands, recording.command_times
    if len(commands) == 0:
        return {"position": 0.0, "velocity": 0.0, "any": 0.0}
    at_position = ((commands <= spec.lower_limits + position_margin)
                   | (commands >= spec.upper_limits - position_margin)).any(axis=1)
    at_velocity = np.zeros(len(commands), dtype=bool)
    if len(commands) > 1:
        speed = np.abs(np.diff(commands, axis=0)) / np.maximum(np.diff(times), 1e-3)[:, None]
        at_velocity[1:] = (speed > spec.velocity_limits * velocity_margin).any(axis=1)
    return {"position": float(at_position.mean()), "velocity": float(at_velocity.mean()),
            "any": float((at_position | at_velocity).mean())}


def replayed_mask(recording: RunRecording, replay: Replay) -> np.ndarray:
    """(n,) the joint states the replay covers."""
    mask = np.zeros(len(recording.state_times), dtype=bool)
    for start, end in replay.segments:
        mask[start:end] = True
    return mask


def plot_joints(recording: RunRecording, replay: Replay, out_dir: Path, title: str,
                baseline: Optional[Replay] = None, baseline_label: str = "") -> Dict[str, Path]:
    """One PNG per joint (recorded, simulated and commanded position against time, and the error
    below), and ``overview.png``: every joint's error in one picture, the gap at a glance.

    :return: name -> path of each picture written.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    mask = replayed_mask(recording, replay)
    t = recording.state_times - recording.state_times[0]
    commanded = commands_at(recording.state_times, recording.command_times, recording.commands)
    written: Dict[str, Path] = {}
    simulated = np.where(mask[:, None], replay.positions, np.nan)
    errors_deg = np.degrees(simulated - recording.positions)
    baseline_deg = (np.degrees(np.where(replayed_mask(recording, baseline)[:, None], baseline.positions, np.nan)
                               - recording.positions) if baseline is not None else None)
    for joint, name in enumerate(recording.joint_names):
        fig, axes = plt.subplots(2, 1, figsize=(10, 5), sharex=True, gridspec_kw={"height_ratios": [2, 1]})
        axes[0].plot(t, np.degrees(commanded[:, joint]), lw=0.8, color="0.6", label="commanded")
        axes[0].plot(t, np.degrees(recording.positions[:, joint]), lw=1.2, label="recorded (arm)")
        axes[0].plot(t, np.degrees(simulated[:, joint]), lw=1.0, ls="--", label="simulated (replay)")
        axes[0].set(ylabel=f"{name} (deg)", title=f"{title}: {name}")
        axes[0].legend(fontsize=8, loc="best")
        if baseline_deg is not None:
            axes[1].plot(t, baseline_deg[:, joint], lw=0.8, color="tab:red", alpha=0.6, label=baseline_label)
        axes[1].plot(t, errors_deg[:, joint], lw=0.8, color="tab:green", label="simulated - recorded")
        axes[1].axhline(0.0, color="0.3", lw=0.5)
        axes[1].set(xlabel="time (s)", ylabel="error (deg)")
        axes[1].legend(fontsize=7, loc="best")
        for axis in axes:
            axis.grid(alpha=0.3)
        fig.tight_layout()
        path = out_dir / f"joint_{name}.png"
        fig.savefig(path, dpi=90)
        plt.close(fig)
        written[name] = path
    fig, axes = plt.subplots(len(recording.joint_names), 1, figsize=(10, 9), sharex=True)
    for joint, (axis, name) in enumerate(zip(axes, recording.joint_names)):
        if baseline_deg is not None:
            axis.plot(t, baseline_deg[:, joint], lw=0.7, color="tab:red", alpha=0.6, label=baseline_label)
        axis.plot(t, errors_deg[:, joint], lw=0.7, color="tab:green", label="this profile")
        rms = float(np.sqrt(np.nanmean(errors_deg[:, joint] ** 2)))
        axis.set_ylabel(f"{name}\n(deg)", fontsize=8)
        axis.text(0.99, 0.85, f"RMS {rms:.3f} deg", transform=axis.transAxes, ha="right", fontsize=8)
        axis.grid(alpha=0.3)
    axes[0].set_title(f"{title}: simulated minus recorded joint position")
    axes[0].legend(fontsize=7, loc="upper left")
    axes[-1].set_xlabel("time (s)")
    fig.tight_layout()
    path = out_dir / "overview.png"
    fig.savefig(path, dpi=90)
    plt.close(fig)
    written["overview"] = path
    return written


def run_report(recording: RunRecording, replay: Replay, spec: RobotSpec, profile_summary: Dict[str, Any],
               errors_summary: Dict[str, Any], phase_steps: int,
               baseline: Optional[Dict[str, Any]] = None) -> Dict[str, Any]:
    """``report.json``'s content."""
    moving = moving_samples(recording) & replayed_mask(recording, replay)
    real_delay = estimated_delay(recording.state_times, recording.positions, recording.command_times,
                                 recording.commands, moving)
    sim_delay = estimated_delay(recording.state_times, replay.positions, recording.command_times,
                                recording.commands, moving)
    report: Dict[str, Any] = {
        "bag": recording.source,
        "topics": recording.topics,
        "duration_s": round(recording.duration, 3),
        "moving_s": round(recording.moving_time(), 3),
        "joint_states": int(len(recording.state_times)),
        "commands": int(len(recording.command_times)),
        "replayed_segments": len(replay.segments),
        "left_out_pauses": len(recording.pauses),
        "profile": profile_summary,
        "servo_phase_steps": phase_steps,
        "tracking_error": errors_summary,
        "estimated_delay_s": {"recorded": real_delay, "simulated": sim_delay,
                              "difference": sim_delay - real_delay},
        "commands_at_limits": limit_hits(recording, spec),
    }
    if baseline is not None:
        report["baseline"] = baseline
    return report


def joint_table(per_joint: Dict[str, Dict[str, float]], names: Sequence[str]) -> str:
    """A text table of RMS and max error per joint (deg)."""
    lines = ["joint   RMS (deg)   max (deg)"]
    for name in names:
        entry = per_joint[name]
        lines.append(f"{name:<7} {entry['rms_deg']:>9.4f}   {entry['max_deg']:>9.4f}")
    return "\n".join(lines)
