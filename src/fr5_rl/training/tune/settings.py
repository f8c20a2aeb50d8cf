"""An experiment's settings (:class:`ExperimentSettings`, saved as ``tune_settings.json`` for
``--resume``), resolved from the command line and the search file by :func:`build_settings`, and
what the experiment optimises (:data:`METRIC`, :data:`MODE`, on the clock :data:`TIME_ATTR`)."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, Optional

from ...config import ConfigError, check_robot_name, typed
from ..hyperparameters import Hyperparameters
from .search_space import SearchFile, load_search_file, trial_hyperparameters, trial_processes

SETTINGS_FILE = "tune_settings.json"
METRIC, MODE = "success", "max"  # what ASHA and the searcher optimise: the latest evaluation success
TIME_ATTR = "timesteps"  # ASHA's clock: environment steps


@dataclass
class ExperimentSettings:
    """Everything an experiment is made of, saved as ``tune_settings.json`` for ``--resume``."""

    task: str
    algo: str
    samples: int
    search: str
    scheduler: str
    search_file: Dict[str, Any]
    base_hyperparameters: Dict[str, Any]
    timesteps: int
    eval_freq: int
    n_envs: int
    seed: int
    out: str
    storage: str
    #: processes per trial (:func:`trial_processes`); None in settings saved before it existed
    processes: Optional[int] = None

    @property
    def trial_cpus(self) -> int:
        """Processes, and so CPUs, of each trial."""
        return trial_processes(self.n_envs, self.processes)

    @property
    def spec(self) -> SearchFile:
        return typed(SearchFile, self.search_file, f"{self.out}/{SETTINGS_FILE}")

    def to_dict(self) -> Dict[str, Any]:
        return dataclasses.asdict(self)


def build_settings(task: str, algo: str, samples: int, search: str, scheduler: str, out: Path,
                   space_path: Optional[str | Path] = None, max_timesteps: Optional[int] = None,
                   n_envs: Optional[int] = None, seed: int = 0, storage: Optional[str] = None,
                   processes: Optional[int] = None, robot: Optional[str] = None) -> ExperimentSettings:
    """Read the search and hyperparameter files and resolve the per-trial budget.

    :param max_timesteps: caps each trial's ``timesteps`` (smoke runs); evaluations (= reports)
        then come at most every ``max_timesteps / 2`` steps so that a trial reports at least twice.
    :param n_envs: overrides the search file's ``trial.n_envs``.
    :param processes: overrides the search file's ``trial.processes`` (see :func:`trial_processes`).
    :param robot: the arm every trial trains for, over the base file's ``env.robot``.
    :param storage: Tune's storage (a path on a file system every node sees, or a URI such as
        ``s3://bucket/dir``); default ``out`` itself.
    :raises ConfigError: a bad file, or hyperparameters that fail train.py's checks.
    """
    from ..algorithms import check_hyperparameters, load_hyperparameters

    if samples < 1:
        raise ConfigError("--samples must be at least 1")
    spec = load_search_file(algo, task, space_path)
    base = load_hyperparameters(algo, task, spec.base).to_dict()
    if robot is not None:
        base["env"] = {**base.get("env", {}), "robot": check_robot_name(robot)}
    timesteps = min(spec.trial.timesteps, max_timesteps) if max_timesteps else spec.trial.timesteps
    eval_freq = min(spec.trial.eval_freq, max(timesteps // 2, 1))
    n_envs = n_envs or spec.trial.n_envs
    if processes is not None and processes < 1:
        raise ConfigError(f"--processes must be at least 1, got {processes}")
    processes = trial_processes(n_envs, processes if processes is not None else spec.trial.processes)
    # The fixed values must make a valid file on their own (sampled ones are checked per trial).
    probe = trial_hyperparameters(base, spec.fixed, {}, n_envs, timesteps)
    check_hyperparameters(algo, typed(Hyperparameters, probe, f"{spec.base} + fixed"), n_envs, spec.base)
    out = Path(out).resolve()
    return ExperimentSettings(task=task, algo=algo, samples=samples, search=search, scheduler=scheduler,
                              search_file=dataclasses.asdict(spec), base_hyperparameters=base,
                              timesteps=int(timesteps), eval_freq=int(eval_freq), n_envs=int(n_envs),
                              seed=int(seed), out=str(out), storage=storage or str(out), processes=processes)
