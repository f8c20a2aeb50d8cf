"""``rosrun fr5_rl tune.py``: sweep hyperparameters and seeds with Ray Tune, on one machine or a cluster.

Each trial is a train.py run (VecNormalize, checkpoints, evaluation); ASHA stops weak trials.
With no --address (and no RAY_ADDRESS) a local Ray runs on this machine; with --address auto
or HOST:PORT the sweep joins a cluster started with `ray start --head` / `ray start --address=...`.
Results land in --out: results.csv/.json (best first), success_vs_steps.png,
best_hyperparams.yaml (for train.py --hyperparams) and best_model/.

Examples::

    rosrun fr5_rl tune.py --task reach --algo ppo --samples 8      # config/search_ppo_reach.yaml
    rosrun fr5_rl tune.py --samples 2 --max-timesteps 4000 --search random --scheduler none
    rosrun fr5_rl tune.py --samples 32 --address auto --n-envs 4 --out runs/tune_reach
    rosrun fr5_rl tune.py --n-envs 16 --processes 1   # 16 environments in each 1-CPU trial
    rosrun fr5_rl tune.py --resume runs/tune_reach                  # after Ctrl-C or a killed driver
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import List, Optional

from ..env_config import TASK_NAMES
from ..config import ConfigError, robot_names
from ..deploy.bundle import ModelFilesError
from ..help_text import HelpFormatter, plain
from . import fail, script_args


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="tune.py", description=plain(__doc__.split("\n\n")[0]),
                                     epilog=plain(__doc__.split("\n\n", 1)[1]),
                                     formatter_class=HelpFormatter)
    parser.add_argument("--task", choices=TASK_NAMES, default="reach")
    parser.add_argument("--algo", choices=["ppo", "sac", "td3", "tqc"], default="ppo")
    parser.add_argument("--robot", choices=robot_names(), default=None,
                        help="the arm every trial trains for (default: the hyperparameter file's env.robot, else fr5)")
    parser.add_argument("--samples", type=int, default=8, help="trials to sample (8)")
    parser.add_argument("--search", choices=["optuna", "random"], default="optuna")
    parser.add_argument("--scheduler", choices=["asha", "none"], default="asha")
    parser.add_argument("--space", type=Path, default=None,
                        help="search-space YAML (default: config/search_<algo>_<task>.yaml)")
    parser.add_argument("--address", default=None,
                        help="Ray cluster to join: auto or HOST:PORT (default: RAY_ADDRESS, else a local Ray)")
    parser.add_argument("--max-timesteps", type=int, default=None, help="cap on each trial's steps (smoke runs)")
    parser.add_argument("--n-envs", type=int, default=None,
                        help="environments per trial (default: the space file's)")
    parser.add_argument("--processes", type=int, default=None,
                        help="processes stepping each trial's environments, the trainer's included; the CPUs a "
                             "trial declares (default: the space file's trial.processes, else one per environment)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the search itself (0)")
    parser.add_argument("--out", type=Path, default=None, help="output directory (default: runs/tune_<task>_<algo>_<time>)")
    parser.add_argument("--storage", default=None,
                        help="Tune's storage: a directory every node sees (NFS) or s3://...; default: --out")
    parser.add_argument("--resume", type=Path, default=None, metavar="DIR",
                        help="continue the experiment whose --out was DIR")
    return parser


def main(argv: Optional[List[str]] = None) -> int:
    parser = build_parser()
    args = parser.parse_args(script_args(argv))
    from ..training.tune.experiment import TuneExperiment  # after parsing: --help stays fast
    from ..training.tune.settings import build_settings

    try:
        if args.resume is not None:
            experiment = TuneExperiment.from_directory(args.resume, args.address)
        else:
            out = args.out or Path("runs") / f"tune_{args.task}_{args.algo}_{time.strftime('%Y%m%d-%H%M%S')}"
            settings = build_settings(args.task, args.algo, args.samples, args.search, args.scheduler, out,
                                      args.space, args.max_timesteps, args.n_envs, args.seed, args.storage,
                                      args.processes, args.robot)
            experiment = TuneExperiment(settings, args.address)
        rows = experiment.run(resume=args.resume is not None)
    except (ConfigError, ModelFilesError) as error:
        return fail("tune.py", error)
    except KeyboardInterrupt:
        print(f"\ntune.py: interrupted; continue with: tune.py --resume {experiment.out}")
        return 130
    unfinished = [row for row in rows if row["status"] == "error"]
    if rows:
        best = rows[0]
        print(f"tune.py: {len(rows)} trials; best {best['trial_id']}: success {best['success']:.0%} after "
              f"{best['steps']} steps")
    print(f"tune.py: wrote {experiment.out}/results.csv, results.json, success_vs_steps.png, "
          "best_hyperparams.yaml and best_model/")
    if unfinished:
        print(f"tune.py: {len(unfinished)} trials errored (see results.csv); retry them with "
              f"tune.py --resume {experiment.out}")
        return 1
    return 0
