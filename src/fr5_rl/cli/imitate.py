"""``rosrun fr5_rl imitate.py``: learn a policy from the scripted expert with DAgger.

The result is an ordinary model directory that evaluate.py, export_onnx.py and the policy
node take like any trained model. Defaults come from config/dagger_<task>.yaml.
"""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import List, Optional

from ..config import ConfigError, robot_names
from ..deploy.bundle import ModelFilesError
from ..env_config import TASK_NAMES
from ..training.run_settings import DaggerRun
from ..help_text import HelpFormatter, plain
from . import fail, script_args


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="imitate.py", description=plain(__doc__.split("\n\n")[0]),
                                     epilog=plain(__doc__.split("\n\n", 1)[1]), formatter_class=HelpFormatter)
    parser.add_argument("--task", choices=TASK_NAMES, default="grasp")
    parser.add_argument("--hyperparams", default=None,
                        help="DAgger YAML (default: config/dagger_<task>.yaml)")
    parser.add_argument("--run-dir", type=Path, default=None, help="default: runs/<task>_dagger_<time>")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--rounds", type=int, default=None, help="DAgger rounds after the expert round (default: the file's)")
    parser.add_argument("--episodes", type=int, default=None, help="episodes per round (default: the file's)")
    parser.add_argument("--epochs", type=int, default=None, help="fitting epochs per round (default: the file's)")
    parser.add_argument("--eval-episodes", type=int, default=50, help="evaluation episodes per round (50)")
    parser.add_argument("--torch-threads", type=int, default=1, help="(1)")
    parser.add_argument("--workers", type=int, default=1,
                        help="processes rolling out and evaluating episodes (1: serially, in this one)")
    parser.add_argument("--robot", choices=robot_names(), default=None,
                        help="the arm (config/robots/); default: the DAgger file's env.robot, else fr5")
    parser.add_argument("--resume", action="store_true",
                        help="continue --run-dir from the last round it finished (same options as it began with)")
    return parser


def dagger_run(args: argparse.Namespace) -> DaggerRun:
    """The command line's options as a :class:`DaggerRun`."""
    return DaggerRun(task=args.task, hyperparams=args.hyperparams, run_dir=args.run_dir, seed=args.seed,
                     rounds=args.rounds, episodes=args.episodes, epochs=args.epochs,
                     eval_episodes=args.eval_episodes, torch_threads=args.torch_threads, robot=args.robot,
                     workers=args.workers, resume=args.resume)


def main(argv: Optional[List[str]] = None) -> int:
    args = build_parser().parse_args(script_args(argv))
    if args.workers < 1:
        return fail("imitate.py", ValueError(f"--workers must be at least 1, got {args.workers}"))
    if args.resume and args.run_dir is None:
        return fail("imitate.py", ValueError("--resume needs --run-dir: the run to continue"))
    from ..training.imitation import run_dagger

    try:
        return run_dagger(dagger_run(args))
    except (ConfigError, ModelFilesError) as error:
        return fail("imitate.py", error)
