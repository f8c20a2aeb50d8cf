"""Algorithm registry and hyperparameter files (``config/<algo>_<task>.yaml``, rl-zoo style)."""
from __future__ import annotations

from typing import Any, Dict, Type

from ..config import ConfigError, load_yaml


def algorithm_class(name: str) -> Type:
    """SB3 (or sb3-contrib) class for ``ppo``, ``sac``, ``td3`` or ``tqc``."""
    name = name.lower()
    if name in ("ppo", "sac", "td3"):
        import stable_baselines3

        return getattr(stable_baselines3, name.upper())
    if name == "tqc":
        from sb3_contrib import TQC

        return TQC
    raise ConfigError(f"unknown algorithm '{name}'; choose ppo, sac, td3 or tqc")


def load_hyperparameters(algo: str, task: str, path: str | None = None) -> Dict[str, Any]:
    """Read the hyperparameter file and fill defaults; validated by :func:`check_hyperparameters`."""
    data = load_yaml(path or f"{algo}_{task}")
    data.setdefault("algo_kwargs", {})
    data.setdefault("normalize", {"norm_obs": True, "norm_reward": False})
    data.setdefault("env", {})
    data.setdefault("n_timesteps", 1_000_000)
    return data


def check_hyperparameters(algo: str, hyper: Dict[str, Any], n_envs: int) -> None:
    """Catch configuration errors before any training time is spent."""
    kwargs = hyper["algo_kwargs"]
    if n_envs < 1:
        raise ConfigError("--n-envs must be at least 1")
    if algo == "ppo":
        n_steps = int(kwargs.get("n_steps", 2048))
        batch_size = int(kwargs.get("batch_size", 64))
        rollout = n_steps * n_envs
        if rollout % batch_size != 0:
            divisors = [d for d in range(32, min(rollout, 4096) + 1) if rollout % d == 0]
            suggestion = min(divisors, key=lambda d: abs(d - batch_size)) if divisors else 1
            raise ConfigError(
                f"PPO batch_size={batch_size} must divide n_steps * n_envs = {n_steps} * {n_envs} = "
                f"{rollout}; change batch_size (e.g. {suggestion}), n_steps or --n-envs"
            )
        if batch_size < 2:
            raise ConfigError("PPO batch_size must be at least 2")
    else:
        if int(kwargs.get("batch_size", 256)) > int(kwargs.get("buffer_size", 1_000_000)):
            raise ConfigError(f"{algo.upper()} batch_size must not exceed buffer_size")
    if hyper["normalize"].get("norm_reward", False) and algo == "ppo":
        # Allowed, but the seed's pitfall 2 (reward scale drifting mid-run) is worth a warning.
        hyper.setdefault("_warnings", []).append(
            "normalize.norm_reward is on: its running std can blow up after a burst of "
            "collisions; the shipped configs keep it off"
        )
