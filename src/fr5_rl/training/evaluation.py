"""Evaluating policies on held-out seeds, and drawing learning curves: what evaluate.py runs.

Per-episode records (seed, success, failure cause, length, return, final distance), their
summary (success rate with its 95 % Wilson interval, mean length, failure causes), and the
learning curve of a training run.
"""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple

import numpy as np

from ..deploy.bundle import write_json_atomic

HELD_OUT_SEED_START = 1_000_000  # far from every training (0..) and evaluation-callback seed


def wilson_interval(successes: int, trials: int, z: float = 1.959964) -> tuple:
    """95 % Wilson score interval of a success proportion."""
    if trials == 0:
        return (0.0, 1.0)
    phat = successes / trials
    denom = 1.0 + z * z / trials
    centre = (phat + z * z / (2 * trials)) / denom
    half = z * math.sqrt(phat * (1 - phat) / trials + z * z / (4 * trials * trials)) / denom
    return (max(0.0, centre - half), min(1.0, centre + half))


def run_episodes(task: str, env_overrides: Dict[str, Any], make_actor, seeds: List[int],
                 gif_path: Optional[Path] = None) -> List[Dict[str, Any]]:
    """One episode per seed; per-episode records.

    ``make_actor(env)`` returns ``(act, on_reset)``: ``act(obs) -> action`` and a callable run
    after every reset (or None), so actors that read the simulator (the expert) can bind to it.
    """
    from ..envs import FR5Env

    env = FR5Env(task=task, config=env_overrides, render_mode="rgb_array" if gif_path else None)
    act, on_reset = make_actor(env)
    records = []
    frames = []
    for index, seed in enumerate(seeds):
        obs, _ = env.reset(seed=int(seed))
        object_x, object_y = (round(float(value), 5) for value in env.object_position()[:2])
        object_label = env.object_description().label
        if on_reset:
            on_reset()
        done, steps, total, info = False, 0, 0.0, {}
        while not done:
            obs, reward, terminated, truncated, info = env.step(act(obs))
            steps += 1
            total += reward
            done = terminated or truncated
            if gif_path is not None and index == 0 and steps % 2 == 0:
                frames.append(env.render())
        records.append({"seed": int(seed), "success": bool(info.get("is_success", False)),
                        "failure": info.get("failure") or "", "length": steps, "return": round(total, 4),
                        "final_distance_m": round(float(np.linalg.norm(env.object_position() - env.tcp_position())), 5),
                        "object_x": object_x, "object_y": object_y, "object": object_label})
    env.close()
    if gif_path is not None and frames:
        from PIL import Image

        images = [Image.fromarray(frame) for frame in frames]
        images[0].save(gif_path, save_all=True, append_images=images[1:], duration=40, loop=0)
    return records


def summarise(records: List[Dict[str, Any]]) -> Dict[str, Any]:
    n = len(records)
    successes = sum(r["success"] for r in records)
    low, high = wilson_interval(successes, n)
    failures: Dict[str, int] = {}
    for r in records:
        if r["failure"]:
            failures[r["failure"]] = failures.get(r["failure"], 0) + 1
    return {"episodes": n, "successes": successes, "success_rate": successes / n if n else 0.0,
            "success_rate_95ci": [round(low, 4), round(high, 4)],
            "mean_episode_length": float(np.mean([r["length"] for r in records])) if n else 0.0,
            "collision_rate": failures.get("collision", 0) / n if n else 0.0,
            "failures": failures, "by_object": by_object(records)}


def by_object(records: List[Dict[str, Any]]) -> Dict[str, Dict[str, Any]]:
    """Successes, episodes and failure causes per kind of object (records' ``object``:
    ``cylinder``, ``square box``, ``rectangular box``); records without one count as ``unknown``."""
    kinds: Dict[str, Dict[str, Any]] = {}
    for record in records:
        kind = kinds.setdefault(record.get("object") or "unknown", {"successes": 0, "episodes": 0, "failures": {}})
        kind["episodes"] += 1
        if record["success"]:
            kind["successes"] += 1
        elif record.get("failure"):
            kind["failures"][record["failure"]] = kind["failures"].get(record["failure"], 0) + 1
    return dict(sorted(kinds.items()))


def format_count(value: float, _position: Any = None) -> str:
    """A step or sample count as a short axis label: 0 -> "0", 500 -> "500", 200000 -> "200k",
    1200000 -> "1.2M" (three significant digits). Usable as a matplotlib FuncFormatter."""
    if value == 0:
        return "0"
    for divisor, suffix in ((1e9, "G"), (1e6, "M"), (1e3, "k")):
        shown = f"{value / divisor:.3g}"
        if abs(float(shown)) >= 1:
            return f"{shown}{suffix}"
    return f"{value:.3g}"


TRAINING_WINDOW = 500  # training episodes per point of the training-success curve


def training_success(monitor_dir: Path) -> Optional[Tuple[np.ndarray, np.ndarray]]:
    """Training episodes' success, from a run's Monitor files: (environment steps at each
    episode's end, success rate over the last :data:`TRAINING_WINDOW` episodes); None when
    there are none. Episodes of all environments in the order they ended."""
    episodes = []
    for path in sorted(monitor_dir.glob("*.monitor.csv")) if monitor_dir.is_dir() else []:
        with open(path, newline="", encoding="utf-8") as stream:
            next(stream)  # the JSON header line
            for row in csv.DictReader(stream):
                episodes.append((float(row["t"]), int(row["l"]), row.get("is_success") == "True"))
    if not episodes:
        return None
    episodes.sort()
    steps = np.cumsum([length for _, length, _ in episodes])
    success = np.array([ok for _, _, ok in episodes], dtype=float)
    window = np.ones(min(TRAINING_WINDOW, len(success)))
    rate = np.convolve(success, window, mode="full")[:len(success)] / np.minimum(np.arange(1, len(success) + 1), len(window))
    return steps, rate


def plot_learning_curve(run_dir: Path, out: Path) -> Path:
    """PNG of a run's evaluation success against training experience.

    RL runs (train.py): success and mean return of the evaluation callback against steps.
    DAgger runs (imitate.py): the learner's evaluation success after each round against the
    number of expert-labelled samples. Counts on the x axis read 200k, 1.2M (:func:`format_count`).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter, MaxNLocator

    def count_axis(axis) -> None:
        axis.xaxis.set_major_locator(MaxNLocator(nbins=6, steps=[1, 2, 2.5, 5, 10], integer=True, min_n_ticks=3))
        axis.xaxis.set_major_formatter(FuncFormatter(format_count))

    summary_path = run_dir / "summary.json"
    summary = json.loads(summary_path.read_text()) if summary_path.is_file() else {}
    machine = summary.get("machine", {})
    if summary.get("method") == "dagger":
        rounds = [h for h in summary["history"] if "eval_success" in h]
        fig, ax = plt.subplots(1, 1, figsize=(6, 3.6))
        ax.plot([h["samples"] for h in rounds], [100 * h["eval_success"] for h in rounds], marker="o", label="task")
        if any(h.get("eval_success_training_env") is not None for h in rounds):
            ax.plot([h["samples"] for h in rounds], [100 * (h.get("eval_success_training_env") or 0) for h in rounds],
                    marker="s", label="randomised training env")
            ax.legend(loc="lower right", fontsize=8)
        for h in rounds:
            ax.annotate(f"{h['wall_s'] / 60:.1f} min", (h["samples"], 100 * h["eval_success"]),
                        textcoords="offset points", xytext=(0, -14), ha="center", fontsize=7)
        ax.set(xlabel="expert-labelled samples (DAgger rounds)", ylabel="evaluation success (%)", ylim=(-2, 105))
        ax.grid(alpha=0.3)
        count_axis(ax)
        fig.suptitle(f"{summary.get('task')} / DAgger from the scripted expert, {machine.get('cores')} cores")
    else:
        data = np.load(run_dir / "eval" / "evaluations.npz")
        steps = data["timesteps"]
        fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
        if "successes" in data and len(data["successes"]):
            ax[0].plot(steps, data["successes"].mean(axis=1) * 100.0, marker="o", ms=3, label="evaluation (plain task)")
        training = training_success(run_dir / "monitor")
        if training is not None:
            ax[0].plot(training[0], training[1] * 100.0, lw=1, alpha=0.7,
                       label=f"training episodes (last {TRAINING_WINDOW})")
        curriculum_path = run_dir / "curriculum.json"
        history = json.loads(curriculum_path.read_text()).get("history", []) if curriculum_path.is_file() else []
        if history:
            from .curriculum import PLAIN_LEVEL

            levels = [PLAIN_LEVEL if h["reach_back"] is None else h["reach_back"] for h in history]
            changes = [h["num_timesteps"] for h in history]
            last_step = max([*changes, *steps, *(training[0][-1:] if training is not None else [])])
            back = ax[0].twinx()  # each level holds until the next change, the last to the run's end
            back.step(changes + [last_step], levels + levels[-1:], where="post", color="grey", ls="--", lw=1)
            back.set(ylim=(0, PLAIN_LEVEL + 0.05), ylabel=f"expert-start reach-back ({PLAIN_LEVEL:g}: plain)")
        if training is not None or history:
            ax[0].legend(loc="upper left", fontsize=7)
        ax[0].set(xlabel="environment steps", ylabel="success (%)", ylim=(-2, 102), title="success")
        ax[0].grid(alpha=0.3)
        ax[1].plot(steps, data["results"].mean(axis=1))
        ax[1].set(xlabel="environment steps", ylabel="mean evaluation return", title="return")
        ax[1].grid(alpha=0.3)
        for axis in ax:
            count_axis(axis)
        if "time_to_solve_s" in summary:
            fig.suptitle(f"{summary.get('task')} / {summary.get('algo')}: solved "
                         f"({summary.get('target_success', 0.95):.0%}) after "
                         f"{format_count(summary['timesteps_to_solve'])} steps, "
                         f"{summary['time_to_solve_s'] / 60:.1f} min on {machine.get('cores')} cores")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def write_results(summary: Dict[str, Any], records: List[Dict[str, Any]], out: Path, csv_path: Path) -> None:
    """The summary as JSON at ``out`` and one CSV row per episode at ``csv_path``."""
    out.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out, summary)
    with open(csv_path, "w", newline="", encoding="utf-8") as stream:
        writer = csv.DictWriter(stream, fieldnames=list(records[0].keys()))
        writer.writeheader()
        writer.writerows(records)
