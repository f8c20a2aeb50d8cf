"""What a training run is made of: the typed settings that :func:`fr5_rl.training.train.train`
and :func:`fr5_rl.training.imitation.run_dagger` take.

The command lines (:mod:`fr5_rl.cli.train`, :mod:`fr5_rl.cli.imitate`) and the Ray Tune trial
(:func:`fr5_rl.training.tune.trial.run_trial`) build these objects; nothing here knows argparse.

A run directory's ``config.json`` (:meth:`TrainRun.saved_config`) holds what ``--resume`` needs;
:meth:`TrainRun.resumed` says, option by option, what a resumed run takes from it and what from
the settings given now. This module imports nothing heavy: the command lines import it before
they parse.
"""
from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path
from typing import AbstractSet, Any, Dict, Mapping, Optional

from ..config import ConfigError, check_robot_name

CONFIG_FILE = "config.json"  # in the run directory: what --resume continues

#: What a run *is*: a resumed run always takes these from its ``config.json``, even when given again.
FIXED_ON_RESUME = ("task", "algo", "seed", "n_envs", "timesteps")
#: How a run is watched and stepped: a resumed run takes these from its ``config.json`` unless
#: they were given again (the field names of :class:`TrainRun`).
KEPT_ON_RESUME = ("checkpoint_freq", "eval_freq", "eval_episodes", "eval_envs", "subprocess",
                  "target_success", "eval_min_training_success")


@dataclass(frozen=True)
class TrainRun:
    """One training run (``train.py``'s options), or the resumption of one.

    :param task: ``reach`` or ``grasp``.
    :param algo: ``ppo``, ``sac``, ``td3`` or ``tqc``.
    :param hyperparams: the hyperparameter file, a path or a name in ``config/``; None:
        ``config/<algo>_<task>.yaml``. Not read when resuming (the run's ``config.json`` holds the
        resolved hyperparameters).
    :param n_envs: parallel environments; None (or 0): the hyperparameter file's ``n_envs``.
    :param seed: seed of the model and of environment ``rank`` (``seed + rank``); evaluation
        episodes use ``seed + 10000``.
    :param timesteps: environment steps (summed over the environments) the run ends at; None
        (or 0): the hyperparameter file's ``n_timesteps``. With ``init_from`` they count this
        run's steps only.
    :param run_dir: the run directory; None: ``runs/<task>_<algo>_<YYYYmmdd-HHMMSS>`` (a new run only).
    :param resume: continue ``run_dir`` from its last checkpoint (``run_dir/config.json`` must
        exist; build the settings with :meth:`resumed`).
    :param init_from: a model directory to start from (weights and VecNormalize statistics, same
        task and algorithm) instead of from scratch; ignored when resuming.
    :param checkpoint_freq: environment steps between checkpoints (``checkpoints/latest``).
    :param eval_freq: environment steps between evaluations (rounded down to whole vector steps
        of ``n_envs`` environments, at least one).
    :param eval_episodes: episodes per evaluation.
    :param eval_envs: environments the evaluation's episodes are spread over (SB3's
        ``evaluate_policy`` gives environment ``i`` ``(eval_episodes + i) // eval_envs`` of
        them), stepped like the training ones on ``processes`` cores; capped at
        ``eval_episodes``. A fixed number, not one per core, so that a run evaluates the same
        episodes on any machine.
    :param target_success: evaluation success rate (0..1) that counts as solved, for the time to solve.
    :param stop_at_success: stop training once ``target_success`` is reached.
    :param eval_min_training_success: skip an evaluation while the training episodes since the
        last one succeeded at a lower rate (0..1; 0: evaluate every ``eval_freq`` steps).
    :param subprocess: step the environments in worker processes; False: all in this process.
    :param processes: processes stepping the environments, this one included; None: one per
        available core, at most ``n_envs``. Speed only: results are the same.
    :param start_method: multiprocessing start method of the workers: ``forkserver``, or
        ``spawn`` inside a Ray worker (forking a process that runs Ray's threads can hang).
    :param progress: show a progress bar.
    :param torch_threads: threads of torch's CPU operations (at least 1 is used).
    :param driver_profile: a driver profile (``fit_driver.py``'s, or written by hand; a path or a
        name in ``config/``) whose servo delay, state age, physics step and response the
        perturbed episodes draw (:meth:`fr5_rl.sim.driver_profile.DriverProfile.env_randomisation`),
        over the hyperparameter file's; None: the file's own.
    :param robot: the arm to train for (``config/robots/<robot>.yaml``), over the hyperparameter
        file's ``env.robot``; None: the file's, else env.yaml's (``fr5``). A resumed run keeps its own.
    :param force: a new run may replace what ``run_dir`` holds (without it, an existing run refuses).
    """

    task: str = "reach"
    algo: str = "ppo"
    hyperparams: Optional[str] = None
    n_envs: Optional[int] = None
    seed: int = 0
    timesteps: Optional[int] = None
    run_dir: Optional[Path] = None
    resume: bool = False
    init_from: Optional[Path] = None
    checkpoint_freq: int = 20_000
    eval_freq: int = 20_000
    eval_episodes: int = 40
    eval_envs: int = 8
    target_success: float = 0.95
    stop_at_success: bool = False
    eval_min_training_success: float = 0.0
    subprocess: bool = True
    processes: Optional[int] = None
    start_method: str = "forkserver"
    progress: bool = True
    torch_threads: int = 1
    driver_profile: Optional[str] = None
    robot: Optional[str] = None
    force: bool = False

    def check(self) -> None:
        """Refuse values no run can use.

        :raises ConfigError: ``processes``, ``eval_envs`` or ``eval_episodes`` below 1,
            ``eval_min_training_success`` outside [0, 1].
        """
        if self.eval_episodes < 1:
            raise ConfigError(f"--eval-episodes must be at least 1, got {self.eval_episodes}")
        if self.processes is not None and self.processes < 1:
            raise ConfigError(f"--processes must be at least 1, got {self.processes}")
        if self.eval_envs < 1:
            raise ConfigError(f"--eval-envs must be at least 1, got {self.eval_envs}")
        if not 0.0 <= float(self.eval_min_training_success) <= 1.0:
            raise ConfigError(f"--eval-min-training-success must be in [0, 1], got {self.eval_min_training_success}")
        if self.robot is not None:
            check_robot_name(self.robot)

    def resumed(self, saved: Mapping[str, Any], typed_again: AbstractSet[str] = frozenset()) -> "TrainRun":
        """These settings merged with a run's saved ``config.json`` (:func:`read_run_config`), for
        ``resume``: the options of :data:`FIXED_ON_RESUME` always come from ``saved``; those of
        :data:`KEPT_ON_RESUME` come from ``saved`` (when it has them) unless their name is in
        ``typed_again``; every other option is this object's.

        :param saved: the run's ``config.json``.
        :param typed_again: field names whose values the user gave again for this resumption
            (on the command line); their values here win over the saved ones.
        :raises ConfigError: ``saved`` lacks an option of :data:`FIXED_ON_RESUME`.
        """
        unknown = set(typed_again) - {field.name for field in dataclasses.fields(self)}
        if unknown:
            raise ValueError(f"typed_again names no TrainRun field: {sorted(unknown)}")
        missing = [name for name in FIXED_ON_RESUME if name not in saved]
        if missing:
            raise ConfigError(f"{CONFIG_FILE}: missing key '{missing[0]}'; it is not a run's config.json")
        changes = {name: saved[name] for name in FIXED_ON_RESUME}
        for name in KEPT_ON_RESUME:
            key = _SAVED_AS.get(name, name)
            if name in typed_again:
                continue
            if key in saved:
                changes[name] = not saved[key] if name == "subprocess" else saved[key]
            elif name in _BEFORE_THE_KEY:
                changes[name] = _BEFORE_THE_KEY[name]
        return dataclasses.replace(self, **changes)

    def saved_config(self, hyperparams_resolved: Mapping[str, Any], **extra: Any) -> Dict[str, Any]:
        """``config.json``'s contents: everything :meth:`resumed` reads back, with the resolved
        hyperparameter file (``Hyperparameters.to_dict()``) and ``extra`` keys (e.g. ``init_from``)."""
        return {"task": self.task, "algo": self.algo, "seed": self.seed, "n_envs": self.n_envs,
                "timesteps": self.timesteps, "hyperparams_resolved": dict(hyperparams_resolved),
                "checkpoint_freq": self.checkpoint_freq, "eval_freq": self.eval_freq,
                "eval_episodes": self.eval_episodes, "eval_envs": self.eval_envs,
                "no_subprocess": not self.subprocess,
                "target_success": self.target_success,
                "eval_min_training_success": float(self.eval_min_training_success),
                # a record only: the profile's randomisation is in hyperparams_resolved, which a resume reads
                "driver_profile": self.driver_profile,
                # a record only: the arm is in hyperparams_resolved's env, which a resume reads
                "robot": self.robot, **extra}


# config.json keys that differ from the field's name (kept as they were: older runs resume too)
_SAVED_AS = {"subprocess": "no_subprocess"}
# What a config.json written before a key existed ran with, where that differs from today's
# default: such a run resumes evaluating as it began (one environment, not eight).
_BEFORE_THE_KEY = {"eval_envs": 1}


def read_run_config(run_dir: Optional[Path]) -> Dict[str, Any]:
    """A run directory's ``config.json``.

    :raises ConfigError: no ``run_dir``, or it holds no ``config.json``.
    """
    if run_dir is None or not (Path(run_dir) / CONFIG_FILE).is_file():
        raise ConfigError("--resume needs --run-dir pointing at an existing run (with config.json)")
    return json.loads((Path(run_dir) / CONFIG_FILE).read_text())


@dataclass(frozen=True)
class DaggerRun:
    """One DAgger run (``imitate.py``'s options); the rest comes from the DAgger file.

    :param task: ``reach`` or ``grasp``.
    :param hyperparams: the DAgger file, a path or a name in ``config/``; None:
        ``config/dagger_<task>.yaml``.
    :param run_dir: the run directory; None: ``runs/<task>_dagger_<YYYYmmdd-HHMMSS>``.
    :param seed: seed of the demonstrations, the network and the fitting; evaluation episodes
        use ``seed + 10000``.
    :param rounds: DAgger rounds after the expert's round; None: the file's ``dagger.rounds``.
    :param episodes: episodes rolled out per round; None (or 0): the file's ``dagger.episodes``.
    :param epochs: fitting epochs per round; None (or 0): the file's ``dagger.epochs``.
    :param eval_episodes: evaluation episodes per round (and per evaluated environment).
    :param torch_threads: threads of torch's CPU operations.
    :param robot: the arm (``config/robots/``), over the DAgger file's ``env.robot``; None: the file's, else fr5.
    :param workers: processes that roll out and evaluate episodes; 1: in this process, serially
        (the labels then match runs from before workers existed; with more they depend on the
        count, reproducibly).
    :param resume: continue ``run_dir`` from the last round it finished (its ``dagger_state/``):
        the data set, the actor, the history and the random generator come back, so the resumed
        run labels and fits what the unbroken one would have (given the same ``workers``).
    """

    task: str = "grasp"
    hyperparams: Optional[str] = None
    run_dir: Optional[Path] = None
    seed: int = 0
    rounds: Optional[int] = None
    episodes: Optional[int] = None
    epochs: Optional[int] = None
    eval_episodes: int = 50
    torch_threads: int = 1
    robot: Optional[str] = None
    workers: int = 1
    resume: bool = False
