"""``rosrun fr5_rl evaluate.py MODEL_DIR``: success rate of a trained policy on held-out seeds.

Writes ``episodes.csv`` (one row per episode) and a JSON summary (success rate with its 95 %
Wilson interval, mean episode length, collision rate, the seeds). ``--gif`` records one
rollout headless; ``--plot RUN_DIR`` draws the learning curve of a training run. Use
``--expert`` instead of a model directory to measure the scripted expert, and ``--config`` /
``--randomise`` to evaluate under noise, latency, mass and friction changes.
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import sys
import time
from pathlib import Path
from typing import Any, Dict, List, Optional

import numpy as np

from .artifacts import EVAL_FILE, ModelFilesError, write_json_atomic

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
                        "final_distance_m": round(float(np.linalg.norm(env.object_position() - env.tcp_position())), 5)})
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
            "failures": failures}


def plot_learning_curve(run_dir: Path, out: Path) -> Path:
    """PNG of a run's evaluation success against training experience.

    RL runs (train.py): success and mean return of the evaluation callback against steps.
    DAgger runs (imitate.py): the learner's evaluation success after each round against the
    number of expert-labelled samples.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

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
        fig.suptitle(f"{summary.get('task')} / DAgger from the scripted expert, {machine.get('cores')} cores")
    else:
        data = np.load(run_dir / "eval" / "evaluations.npz")
        steps = data["timesteps"]
        fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
        if "successes" in data and len(data["successes"]):
            ax[0].plot(steps, data["successes"].mean(axis=1) * 100.0, marker="o", ms=3)
        ax[0].set(xlabel="environment steps", ylabel="evaluation success (%)", ylim=(-2, 102), title="success")
        ax[0].grid(alpha=0.3)
        ax[1].plot(steps, data["results"].mean(axis=1))
        ax[1].set(xlabel="environment steps", ylabel="mean evaluation return", title="return")
        ax[1].grid(alpha=0.3)
        if "time_to_solve_s" in summary:
            fig.suptitle(f"{summary.get('task')} / {summary.get('algo')}: solved "
                         f"({summary.get('target_success', 0.95):.0%}) after {summary['timesteps_to_solve']} steps, "
                         f"{summary['time_to_solve_s'] / 60:.1f} min on {machine.get('cores')} cores")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def main(argv: Optional[List[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("model_dir", type=Path, nargs="?", help="model directory (model.zip + vecnormalize.pkl + meta.json)")
    parser.add_argument("--expert", choices=["reach", "grasp"], help="evaluate the scripted expert on this task")
    parser.add_argument("--backend", choices=["torch", "onnx"], default="torch")
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--seed-start", type=int, default=HELD_OUT_SEED_START)
    parser.add_argument("--config", type=str, default=None,
                        help="JSON env overrides merged over the model's, e.g. '{\"randomisation\": {\"enabled\": true}}'")
    parser.add_argument("--training-env", action="store_true",
                        help="evaluate with the model's training overrides (e.g. its randomisation)")
    parser.add_argument("--out", type=Path, default=None, help="summary JSON (default: MODEL_DIR/eval.json)")
    parser.add_argument("--csv", type=Path, default=None, help="per-episode CSV (default: beside the summary)")
    parser.add_argument("--gif", type=Path, default=None, help="record the first episode as a GIF")
    parser.add_argument("--plot", type=Path, default=None, metavar="RUN_DIR", help="draw RUN_DIR's learning curve")
    parser.add_argument("--plot-out", type=Path, default=None)
    args = parser.parse_args(argv if argv is not None else [a for a in sys.argv[1:] if not a.startswith("__")])

    if args.plot:
        out = plot_learning_curve(args.plot, args.plot_out or args.plot / "learning_curve.png")
        print(f"wrote {out}")
        if args.model_dir is None and args.expert is None:
            return 0
    overrides: Dict[str, Any] = {}
    t0 = time.time()
    if args.expert:
        from ..expert import ScriptedExpert

        task, label = args.expert, "scripted expert"

        def make_actor(env):
            expert = ScriptedExpert(env)
            return expert.act, expert.reset
    else:
        if args.model_dir is None:
            parser.error("give a MODEL_DIR, --expert TASK or --plot RUN_DIR")
        from ..policy import load_policy

        try:
            policy = load_policy(args.model_dir, args.backend)
        except ModelFilesError as error:
            print(f"evaluate.py: {error}", file=sys.stderr)
            return 2
        task, label = policy.task, str(args.model_dir)
        # The task as registered, not the training variant (which may randomise); use
        # --training-env for that.
        overrides = dict(policy.meta.get("env_overrides", {})) if args.training_env else {}

        def make_actor(env):
            return policy.act, None
    if args.config:
        from ..config import deep_update, load_yaml

        overrides = deep_update(deep_update(load_yaml("env"), overrides), json.loads(args.config))
    seeds = list(range(args.seed_start, args.seed_start + args.episodes))
    records = run_episodes(task, overrides, make_actor, seeds, gif_path=args.gif)
    summary = summarise(records)
    summary.update({"policy": label, "task": task, "backend": args.backend if not args.expert else "expert",
                    "deterministic": True, "seeds": [seeds[0], seeds[-1]], "env_overrides": overrides,
                    "eval_wall_time_s": round(time.time() - t0, 1)})
    if not args.expert:
        meta = policy.meta
        summary.update({"algo": meta["algo"], "training_steps": meta.get("num_timesteps"),
                        "training_wall_time_s": meta.get("training_wall_time_s"), "machine": meta.get("machine")})
    out = args.out or (args.model_dir / EVAL_FILE if args.model_dir else Path(f"eval_{task}_expert.json"))
    out.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out, summary)
    csv_path = args.csv or out.with_suffix(".csv")
    with open(csv_path, "w", newline="", encoding="utf-8") as stream:
        writer = csv.DictWriter(stream, fieldnames=list(records[0].keys()))
        writer.writeheader()
        writer.writerows(records)
    low, high = summary["success_rate_95ci"]
    print(f"{label} on {task}: success {summary['successes']}/{summary['episodes']} = "
          f"{summary['success_rate']:.1%} (95% CI {low:.1%}-{high:.1%}), mean length "
          f"{summary['mean_episode_length']:.1f}, collisions {summary['collision_rate']:.1%}")
    print(f"wrote {out} and {csv_path}")
    return 0
