"""``rosrun fr5_rl evaluate.py MODEL_DIR``: success rate of a trained policy on held-out seeds.

Writes a JSON summary (success rate with its 95 % Wilson interval, mean episode length,
failure causes, the seeds) and a CSV with one row per episode. ``--gif`` records one rollout
headless; ``--plot RUN_DIR`` draws the learning curve of a training run. ``--expert TASK``
measures the scripted expert instead of a model; ``--config`` / ``--training-env`` evaluate
under noise, latency, mass and friction changes. ``--ray`` spreads the episodes over a Ray
cluster (``--address``, or RAY_ADDRESS, else a local Ray): same seeds, same files, same outcomes.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any, Dict, List, Optional

from ..config import ConfigError, robot_names
from ..env_config import TASK_NAMES
from ..deploy.bundle import META_FILE, ModelFilesError
from ..training.evaluation import HELD_OUT_SEED_START
from ..help_text import HelpFormatter, plain
from . import fail, script_args


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="evaluate.py", description=plain(__doc__.split("\n\n")[0]),
                                     epilog=plain(__doc__.split("\n\n", 1)[1]), formatter_class=HelpFormatter)
    parser.add_argument("model_dir", type=Path, nargs="?", help="model directory (meta.json + the backend's files)")
    parser.add_argument("--expert", choices=TASK_NAMES, help="evaluate the scripted expert on this task")
    parser.add_argument("--robot", choices=robot_names(), default=None,
                        help="the arm: the expert's (default fr5); a model trained for another arm refuses")
    parser.add_argument("--backend", choices=["torch", "onnx"], default="torch")
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--seed-start", type=int, default=HELD_OUT_SEED_START)
    parser.add_argument("--config", type=str, default=None,
                        help="JSON env overrides merged over the model's, e.g. '{\"randomisation\": {\"enabled\": true}}'")
    parser.add_argument("--training-env", action="store_true",
                        help="evaluate with the model's training overrides (e.g. its randomisation)")
    parser.add_argument("--out", type=Path, default=None,
                        help="summary JSON (default: eval_<MODEL_DIR's name>.json in the current directory)")
    parser.add_argument("--force", action="store_true",
                        help="write over a model directory's own eval.json (or a file there) if --out points at it")
    parser.add_argument("--csv", type=Path, default=None, help="per-episode CSV (default: beside the summary)")
    parser.add_argument("--gif", type=Path, default=None, help="record the first episode as a GIF")
    parser.add_argument("--no-map", action="store_true",
                        help="skip the success map (<summary>_map.png/.json: success and failures by object placement)")
    parser.add_argument("--plot", type=Path, default=None, metavar="RUN_DIR", help="draw RUN_DIR's learning curve")
    parser.add_argument("--plot-out", type=Path, default=None)
    parser.add_argument("--ray", action="store_true", help="spread the episodes over a Ray cluster (Ray tasks)")
    parser.add_argument("--address", default=None,
                        help="with --ray: the cluster, auto or HOST:PORT (default: RAY_ADDRESS, else a local Ray)")
    return parser


def main(argv: Optional[List[str]] = None) -> int:
    parser = build_parser()
    args = parser.parse_args(script_args(argv))
    if args.model_dir is None and args.expert is None and args.plot is None:
        parser.error("give a MODEL_DIR, --expert TASK or --plot RUN_DIR")
    if args.model_dir is not None and args.expert is not None:
        parser.error("give a MODEL_DIR or --expert TASK, not both: --expert evaluates the scripted expert, not a model")
    try:
        return evaluate(args)
    except (ConfigError, ModelFilesError) as error:
        return fail("evaluate.py", error)
    except json.JSONDecodeError as error:
        return fail("evaluate.py", f"--config is not valid JSON: {error}")


def check_writable(out: Optional[Path], force: bool) -> None:
    """Refuse, before any episode runs, an ``--out`` that would replace a file in a model
    directory (a shipped model's eval.json, say) unless ``force``."""
    if out is None or force:
        return
    target = Path(out).resolve()
    if (target.parent / META_FILE).is_file() and any(target.with_suffix(suffix).exists()
                                                     for suffix in (".json", ".csv", ".png")):
        raise ConfigError(f"{out} would replace a result in the model directory {target.parent}: pass another --out, "
                          "or --force to replace it")


def evaluate(args: argparse.Namespace) -> int:
    from ..training.evaluation import plot_learning_curve, run_episodes, summarise, write_results

    if args.plot:
        out = plot_learning_curve(args.plot, args.plot_out or args.plot / "learning_curve.png")
        print(f"wrote {out}")
        if args.model_dir is None and args.expert is None:
            return 0
    overrides: Dict[str, Any] = {}
    t0 = time.time()
    meta: Dict[str, Any] = {}
    if args.expert:
        from ..expert import ScriptedExpert

        task, label = args.expert, "scripted expert"
        if args.robot:
            overrides["robot"] = args.robot

        def make_actor(env):
            expert = ScriptedExpert(env)
            return expert.act, expert.reset
    else:
        from ..deploy.policy import load_policy

        policy = load_policy(args.model_dir, args.backend, expected_robot=args.robot)
        task, label, meta = policy.task, str(args.model_dir), policy.meta
        # The task as registered, not the training variant (which may randomise; use
        # --training-env for that), with the observation and action the policy was trained on.
        overrides = dict(meta.get("env_overrides", {})) if args.training_env else policy.deployment_overrides()

        def make_actor(env):
            return policy.act, None
    if args.config:
        from ..config import deep_update

        # Not strict: the environment refuses unknown keys when it loads the result.
        overrides = deep_update(overrides, json.loads(args.config), strict=False)
    seeds = list(range(args.seed_start, args.seed_start + args.episodes))
    check_writable(args.out, args.force)
    if getattr(args, "ray", False):
        if args.gif:
            raise ConfigError("--gif records on this machine; run it without --ray")
        from ..training.ray_eval import run_episodes_on_ray

        records, nodes = run_episodes_on_ray(task, overrides, seeds, None if args.expert else args.model_dir,
                                             args.backend, args.address)
        print(f"evaluated on Ray: {len(nodes)} tasks on {len(set(nodes))} nodes")
    else:
        records = run_episodes(task, overrides, make_actor, seeds, gif_path=args.gif)
        if args.gif:
            print(f"wrote {args.gif}")
    summary = summarise(records)
    summary.update({"policy": label, "task": task, "backend": args.backend if not args.expert else "expert",
                    "deterministic": True, "seeds": [seeds[0], seeds[-1]], "env_overrides": overrides,
                    "eval_wall_time_s": round(time.time() - t0, 1)})
    if meta:
        summary.update({"algo": meta["algo"], "training_steps": meta.get("num_timesteps"),
                        "training_wall_time_s": meta.get("training_wall_time_s"), "machine": meta.get("machine")})
    out = args.out or Path(f"eval_{Path(args.model_dir).resolve().name}.json" if args.model_dir
                           else f"eval_{task}_expert.json")
    csv_path = args.csv or out.with_suffix(".csv")
    write_results(summary, records, out, csv_path)
    if not args.no_map:
        from ..env_config import load_env_config
        from ..training.success_map import write_success_map

        maps = write_success_map(records, load_env_config(overrides), out.with_name(out.stem + "_map"),
                                 f"{label} on {task}: {summary['successes']}/{summary['episodes']} "
                                 f"(seeds {seeds[0]}-{seeds[-1]})")
        print(f"wrote {maps[1]} and {maps[0]}")
    low, high = summary["success_rate_95ci"]
    print(f"{label} on {task}: success {summary['successes']}/{summary['episodes']} = "
          f"{summary['success_rate']:.1%} (95% CI {low:.1%}-{high:.1%}), mean length "
          f"{summary['mean_episode_length']:.1f}, collisions {summary['collision_rate']:.1%}")
    print(f"wrote {out} and {csv_path}")
    return 0
