"""The hyperparameter file of an algorithm and task (``config/<algo>_<task>.yaml``), loaded and
checked against the Stable-Baselines3 algorithm it configures (the file's schema and its reading:
:mod:`fr5_rl.training.hyperparameters`)."""
from __future__ import annotations

import inspect
import math
from pathlib import Path
from typing import List, Optional

from ..config import ConfigError, package_root, typed
from ..deploy.bundle import algorithm_class
from .hyperparameters import Hyperparameters, hyperparameter_path, read_hyperparameter_file

# Constructor arguments the trainer sets itself: a hyperparameter file must not.
TRAINER_OWNED = ("env", "seed", "device", "tensorboard_log", "verbose", "_init_setup_model")


def hyperparameter_source(algo: str, task: str, path: Optional[str | Path] = None) -> str | Path:
    """The file to read: ``path`` when given, else ``config/<algo>_<task>.yaml``."""
    return path or f"{algo}_{task}"


def load_hyperparameters(algo: str, task: str, path: Optional[str | Path] = None) -> Hyperparameters:
    """Read and type-check a hyperparameter file (with its ``base``, see
    :func:`~fr5_rl.training.hyperparameters.read_hyperparameter_file`); :func:`check_hyperparameters`
    checks the rest."""
    source = hyperparameter_path(hyperparameter_source(algo, task, path))
    try:
        shown = source.resolve().relative_to(package_root())
    except ValueError:  # a file outside the package
        shown = source
    return typed(Hyperparameters, read_hyperparameter_file(source), str(shown))


def check_hyperparameters(algo: str, hyper: Hyperparameters, n_envs: int, source: str = "hyperparameters") -> List[str]:
    """Catch configuration errors before any training time is spent; returns warnings.

    :raises ConfigError: an ``algo_kwargs`` name the algorithm does not take, or settings that
        cannot work together (e.g. a PPO batch size that does not divide the rollout).
    """
    kwargs = hyper.algo_kwargs
    if n_envs < 1:
        raise ConfigError("--n-envs must be at least 1")
    accepted = [name for name in inspect.signature(algorithm_class(algo).__init__).parameters if name != "self"]
    for name in kwargs:
        if name in TRAINER_OWNED:
            raise ConfigError(f"{source}: 'algo_kwargs.{name}' is set by train.py itself; remove it "
                              "(use --seed for the seed)")
        if name not in accepted:
            raise ConfigError(f"{source}: unknown key 'algo_kwargs.{name}' for {algo.upper()}; it takes: "
                              + ", ".join(n for n in accepted if n not in TRAINER_OWNED))
    if algo == "ppo":
        n_steps = int(kwargs.get("n_steps", 2048))
        batch_size = int(kwargs.get("batch_size", 64))
        rollout = n_steps * n_envs
        if rollout % batch_size != 0:
            divisors = [d for d in range(2, min(rollout, 4096) + 1) if rollout % d == 0]
            suggestion = min(divisors, key=lambda d: abs(d - batch_size)) if divisors else None
            # the smallest n_steps that keeps batch_size with these environments
            steps_unit = batch_size // math.gcd(batch_size, n_envs)
            keep_batch = steps_unit * max(1, round(n_steps / steps_unit))
            raise ConfigError(
                f"PPO batch_size={batch_size} must divide n_steps * n_envs = {n_steps} * {n_envs} = "
                f"{rollout}. Keep the config's --n-envs, or set in a --hyperparams file (whose 'base' "
                f"is this config) algo_kwargs.n_steps: {keep_batch}"
                + (f" or algo_kwargs.batch_size: {suggestion}" if suggestion else "")
            )
        if batch_size < 2:
            raise ConfigError("PPO batch_size must be at least 2")
    else:
        if int(kwargs.get("batch_size", 256)) > int(kwargs.get("buffer_size", 1_000_000)):
            raise ConfigError(f"{algo.upper()} batch_size must not exceed buffer_size")
    warnings = []
    if hyper.normalize.norm_reward and algo == "ppo":
        # Allowed, but the seed's pitfall 2 (reward scale drifting mid-run) is worth a warning.
        warnings.append("normalize.norm_reward is on: its running std can blow up after a burst of "
                        "collisions; the shipped configs keep it off")
    return warnings
