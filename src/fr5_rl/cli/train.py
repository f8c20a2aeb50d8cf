"""``rosrun fr5_rl train.py``: train an FR5 policy with Stable-Baselines3.

Examples::

    rosrun fr5_rl train.py --task reach                   # PPO, config/ppo_reach.yaml, the FR5
    rosrun fr5_rl train.py --task reach --robot fr10      # the same for the FR10
    rosrun fr5_rl train.py --task grasp --algo tqc --n-envs 2 --timesteps 300000
    rosrun fr5_rl train.py --resume --run-dir runs/reach_ppo_20261122-1300
    rosrun fr5_rl train.py --task reach --driver-profile fitted.yaml   # fit_driver.py's profile
"""
from __future__ import annotations

import argparse
import copy
import time
from pathlib import Path
from typing import List, Optional, Set

from ..config import ConfigError, robot_names
from ..env_config import TASK_NAMES
from ..deploy.bundle import ModelFilesError
from ..training.run_settings import TrainRun, read_run_config
from ..help_text import HelpFormatter, plain
from . import fail, script_args


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="train.py", description=plain(__doc__.split("\n\n")[0]),
                                     epilog=plain(__doc__.split("\n\n", 1)[1]),
                                     formatter_class=HelpFormatter)
    parser.add_argument("--task", choices=TASK_NAMES, default="reach")
    parser.add_argument("--algo", choices=["ppo", "sac", "td3", "tqc"], default="ppo")
    parser.add_argument("--robot", choices=robot_names(), default=None,
                        help="the arm (config/robots/); default: the hyperparameter file's env.robot, else fr5")
    parser.add_argument("--hyperparams", default=None,
                        help="hyperparameter YAML (default: config/<algo>_<task>.yaml)")
    parser.add_argument("--n-envs", type=int, default=None, help="parallel environments (default: the config's)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--timesteps", type=int, default=None, help="default: the config's n_timesteps")
    parser.add_argument("--run-dir", type=Path, default=None, help="default: runs/<task>_<algo>_<time>")
    parser.add_argument("--resume", action="store_true", help="continue --run-dir from its last checkpoint")
    parser.add_argument("--force", action="store_true", help="replace what --run-dir holds (a new run refuses an "
                                                                 "existing one without it)")
    parser.add_argument("--init-from", type=Path, default=None, metavar="MODEL_DIR",
                        help="start from this trained model (weights + VecNormalize statistics) instead of "
                             "from scratch: fine-tuning, e.g. on a harder randomisation (same task and algo)")
    parser.add_argument("--checkpoint-freq", type=int, default=20_000, help="steps between checkpoints (20000)")
    parser.add_argument("--eval-freq", type=int, default=20_000, help="steps between evaluations (20000)")
    parser.add_argument("--eval-episodes", type=int, default=40, help="episodes per evaluation (40)")
    parser.add_argument("--eval-envs", type=int, default=8, metavar="N",
                        help="environments the evaluation episodes are spread over, stepped on the same cores as "
                             "training (8; a fixed number, so that any machine evaluates the same episodes)")
    parser.add_argument("--target-success", type=float, default=0.95,
                        help="evaluation success rate that counts as solved, for time to solve (0.95)")
    parser.add_argument("--stop-at-success", action="store_true", help="stop once solved")
    parser.add_argument("--eval-min-training-success", type=float, default=0.0, metavar="RATE",
                        help="skip an evaluation while the training episodes since the last one succeeded "
                             "less often than this (0..1; default 0: evaluate every --eval-freq steps)")
    parser.add_argument("--no-subprocess", action="store_true", help="all environments in the trainer's process")
    parser.add_argument("--processes", type=int, default=None, metavar="N",
                        help="processes stepping the environments, this one included (default: one per "
                             "available core, at most n_envs; 1 = --no-subprocess); speed only, results are the same")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--torch-threads", type=int, default=1, help="(1)")
    parser.add_argument("--driver-profile", default=None, metavar="PROFILE.yaml",
                        help="draw the driver's timing and response from this profile (fit_driver.py's, or written "
                             "by hand) in the perturbed episodes, over the hyperparameter file's")
    return parser


# Options whose TrainRun field has another name (the rest are the same).
FIELD_OF_OPTION = {"no_subprocess": "subprocess", "no_progress": "progress"}


def typed_options(parser: argparse.ArgumentParser, argv: List[str]) -> Set[str]:
    """The options ``argv`` gives (by their ``dest``), whatever their values: ``argv`` parsed
    again with every default suppressed, so only what was typed lands in the namespace."""
    quiet = copy.deepcopy(parser)
    for action in quiet._actions:  # (argparse has no public way to reach every action's default)
        action.default = argparse.SUPPRESS
    return set(vars(quiet.parse_args(argv)))


def train_run(args: argparse.Namespace) -> TrainRun:
    """The command line's options as a :class:`TrainRun`."""
    return TrainRun(task=args.task, algo=args.algo, hyperparams=args.hyperparams, n_envs=args.n_envs, seed=args.seed,
                    timesteps=args.timesteps, run_dir=args.run_dir, resume=args.resume, init_from=args.init_from,
                    checkpoint_freq=args.checkpoint_freq, eval_freq=args.eval_freq, eval_episodes=args.eval_episodes,
                    eval_envs=args.eval_envs,
                    target_success=args.target_success, stop_at_success=args.stop_at_success,
                    eval_min_training_success=args.eval_min_training_success, subprocess=not args.no_subprocess,
                    processes=args.processes, progress=not args.no_progress, torch_threads=args.torch_threads,
                    driver_profile=args.driver_profile, robot=args.robot, force=args.force)


def main(argv: Optional[List[str]] = None) -> int:
    t_start = time.time()
    parser = build_parser()
    argv = script_args(argv)
    args = parser.parse_args(argv)
    from ..training.train import train  # after parsing: --help stays fast

    try:
        run = train_run(args)
        if run.resume:  # the run's config.json, but for the options typed again
            typed_again = {FIELD_OF_OPTION.get(dest, dest) for dest in typed_options(parser, argv)}
            run = run.resumed(read_run_config(run.run_dir), typed_again)
        return train(run, t_start)
    except (ConfigError, ModelFilesError) as error:
        return fail("train.py", error)
