"""The search file (``config/search_<algo>_<task>.yaml``): its schema (:class:`SearchFile`), its
samplers as Tune's ``param_space`` (:func:`to_tune_space`), and one trial's hyperparameter file
made from the base file, the fixed and the sampled values (:func:`trial_hyperparameters`)."""
from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, Mapping, Optional

from ...config import ConfigError, load_yaml, typed
from ..ray_compat import import_ray

SEED_KEY = "seed"  # the one space key that is not in the hyperparameter file
SAMPLERS = ("uniform", "loguniform", "quniform", "randint", "choice", "grid")


@dataclass(frozen=True)
class TrialSettings:
    """How each trial trains (``trial:`` of a search file)."""

    n_envs: int
    timesteps: int
    eval_freq: int
    eval_episodes: int
    target_success: float
    stop_at_success: bool
    max_failures: int
    #: processes stepping a trial's environments, the trainer's own included (= the CPUs the
    #: trial declares); None: one per environment. 1 steps them all in the trainer's process.
    processes: Optional[int] = None

    def check(self, source: str) -> None:
        for name in ("n_envs", "timesteps", "eval_freq", "eval_episodes"):
            if getattr(self, name) < 1:
                raise ConfigError(f"{source}: 'trial.{name}' must be at least 1, got {getattr(self, name)}")
        if self.processes is not None and not 1 <= self.processes <= self.n_envs:
            raise ConfigError(f"{source}: 'trial.processes' must be 1..n_envs ({self.n_envs}), got {self.processes}")
        if not 0.0 < self.target_success <= 1.0:
            raise ConfigError(f"{source}: 'trial.target_success' must be in (0, 1], got {self.target_success}")
        if self.max_failures < 0:
            raise ConfigError(f"{source}: 'trial.max_failures' must be 0 or more")


@dataclass(frozen=True)
class AshaSettings:
    """ASHA's rungs (``asha:``): the first after ``grace_period`` steps, then every ``reduction_factor``×."""

    grace_period: int
    reduction_factor: float

    def check(self, source: str) -> None:
        if self.grace_period < 1 or self.reduction_factor <= 1.0:
            raise ConfigError(f"{source}: 'asha' needs grace_period >= 1 and reduction_factor > 1")


@dataclass(frozen=True)
class SearchFile:
    """``config/search_<algo>_<task>.yaml``: the base hyperparameter file, how trials train, ASHA,
    values fixed in every trial and the search space (dotted key -> ``{sampler: arguments}``)."""

    base: str
    trial: TrialSettings
    asha: AshaSettings
    fixed: Dict[str, Any]
    space: Dict[str, Dict[str, Any]]

    def check(self, source: str) -> None:
        if not self.space:
            raise ConfigError(f"{source}: 'space' is empty; give at least one key to search")
        for key, spec in self.space.items():
            check_sampler(key, spec, source)


def check_sampler(key: str, spec: Mapping[str, Any], source: str) -> None:
    """Refuse a space entry that is not one known sampler with arguments of the right shape."""
    if len(spec) != 1 or next(iter(spec)) not in SAMPLERS:
        raise ConfigError(f"{source}: 'space.{key}' must be one of {{{', '.join(SAMPLERS)}: ...}}, got {dict(spec)}")
    (name, values), = spec.items()
    if not isinstance(values, list) or not values:
        raise ConfigError(f"{source}: 'space.{key}.{name}' must be a non-empty list, got {values!r}")
    if name in ("uniform", "loguniform", "quniform", "randint"):
        needed = 3 if name == "quniform" else 2
        try:
            numbers = [float(v) for v in values]
        except (TypeError, ValueError):
            raise ConfigError(f"{source}: 'space.{key}.{name}' needs numbers, got {values!r}") from None
        if len(numbers) != needed or not numbers[0] < numbers[1]:
            raise ConfigError(f"{source}: 'space.{key}.{name}' must be [low, high{', q' if needed == 3 else ''}] "
                              f"with low < high, got {values!r}")
        if name == "loguniform" and numbers[0] <= 0:
            raise ConfigError(f"{source}: 'space.{key}.loguniform' needs low > 0, got {values!r}")


def search_source(algo: str, task: str, path: Optional[str | Path] = None) -> str | Path:
    """The search file to read: ``path`` when given, else ``config/search_<algo>_<task>.yaml``."""
    return path or f"search_{algo}_{task}"


def load_search_file(algo: str, task: str, path: Optional[str | Path] = None) -> SearchFile:
    """Read and check a search file.

    :raises ConfigError: no such file (naming the files there are), or a wrong key or sampler.
    """
    source = search_source(algo, task, path)
    try:
        data = load_yaml(source)
    except ConfigError as error:
        raise ConfigError(f"{error}; write one like config/search_ppo_reach.yaml or pass --space FILE") from None
    return typed(SearchFile, data, str(source))


def to_tune_space(space: Mapping[str, Mapping[str, Any]], search: str) -> Dict[str, Any]:
    """Tune's ``param_space`` for a search file's ``space`` (``tune.uniform`` etc., keys kept).

    :param search: ``random`` or ``optuna`` (which takes no ``grid``).
    :raises ConfigError: ``grid`` with optuna.
    """
    _, tune = import_ray()
    result: Dict[str, Any] = {}
    for key, spec in space.items():
        (name, values), = spec.items()
        if name == "grid":
            if search != "random":
                raise ConfigError(f"space.{key}: 'grid' works with --search random only; use choice for {search}")
            result[key] = tune.grid_search(list(values))
        elif name == "choice":
            result[key] = tune.choice(list(values))
        elif name == "randint":
            result[key] = tune.randint(int(values[0]), int(values[1]))
        elif name == "quniform":
            result[key] = tune.quniform(float(values[0]), float(values[1]), float(values[2]))
        else:
            result[key] = getattr(tune, name)(float(values[0]), float(values[1]))
    return result


def set_dotted(data: Dict[str, Any], key: str, value: Any, source: str = "space") -> None:
    """``data[a][b][c] = value`` for ``key`` = ``a.b.c``; the top-level key must exist already.

    :raises ConfigError: an unknown top-level key, or a path through a value that is no mapping.
    """
    parts = key.split(".")
    if parts[0] not in data:
        raise ConfigError(f"{source}: '{key}' is not in the hyperparameter file (top-level keys: "
                          f"{', '.join(data)}); dotted keys start with one of them")
    node = data
    for part in parts[:-1]:
        node = node.setdefault(part, {})
        if not isinstance(node, dict):
            raise ConfigError(f"{source}: '{key}' goes through '{part}', which is not a mapping")
    node[parts[-1]] = value


def trial_hyperparameters(base: Mapping[str, Any], fixed: Mapping[str, Any], config: Mapping[str, Any],
                          n_envs: int, timesteps: int) -> Dict[str, Any]:
    """The hyperparameter file of one trial: ``base`` with ``fixed`` and the sampled ``config``
    set (``seed`` excepted: it is train.py's --seed), and the trial's n_envs and budget."""
    hyper = copy.deepcopy(dict(base))
    for key, value in list(fixed.items()) + [(k, v) for k, v in config.items() if k != SEED_KEY]:
        set_dotted(hyper, key, value)
    hyper["n_envs"], hyper["n_timesteps"] = int(n_envs), int(timesteps)
    return hyper


def trial_processes(n_envs: int, processes: Optional[int]) -> int:
    """Processes stepping a trial's ``n_envs`` environments, the trainer's included: ``processes``
    capped at ``n_envs``, or one per environment when None.

    This is also the CPUs a trial declares: the trainer steps the first chunk of environments
    itself (:class:`~fr5_rl.training.vec_env.ChunkedSubprocVecEnv`) and learns between rollouts.
    """
    return max(1, min(processes or n_envs, n_envs))
