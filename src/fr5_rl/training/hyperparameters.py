"""Hyperparameter files (``config/<algo>_<task>.yaml``, rl-zoo style, and
``config/dagger_<task>.yaml``): their schemas and how a file is read with the ``base`` it builds on.

Which file an algorithm and task use, and the checks against the Stable-Baselines3 class, are in
:mod:`fr5_rl.training.algorithms`.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, Optional, Tuple

from ..config import ConfigError, check_positive, config_path, deep_update, load_yaml
from ..env_config import load_env_config


@dataclass(frozen=True)
class NormalizeSettings:
    """VecNormalize settings of a hyperparameter file."""

    norm_obs: bool
    norm_reward: bool
    clip_obs: float


@dataclass(frozen=True)
class CriticWarmupSettings:
    """``critic_warmup`` of a hyperparameter file: for the first ``steps`` environment steps only
    the value function trains (the actor held), at ``learning_rate``, so that the first policy
    updates follow advantages of a critic that fits the actor's returns, not noise."""

    steps: int
    learning_rate: float

    def check(self, source: str) -> None:
        check_positive(source, **{"critic_warmup.steps": self.steps, "critic_warmup.learning_rate": self.learning_rate})


@dataclass(frozen=True)
class ExpertStartSettings:
    """``expert_start`` of a hyperparameter file: a reverse curriculum
    (:mod:`fr5_rl.training.curriculum`). Each training episode starts after the scripted expert
    has run ``k`` steps from the reset, the policy taking over there: ``k`` is drawn from the
    last ``reach_back`` of ``max_steps``, first ``first_reach_back``; a share
    ``frontier_share`` of the starts is drawn from the frontier, the starts new since the last
    step back (:class:`fr5_rl.training.curriculum.ExpertStartCurriculum`). The reach-back grows by
    ``step_back`` whenever the last ``window`` training episodes begun at the frontier
    succeeded at a rate of ``promote_at`` or more, up to 1, then once more to plain resets.
    Evaluation always starts from plain resets. ``episodes_per_replay`` starts are drawn at once
    and met along one replay of the expert (1: one replay per episode, each on a new placement).
    ``prepare_ahead`` prepares each environment's next start in a spare environment, in the time
    its process would wait for the others (the same starts whatever the timing; only with
    ``episodes_per_replay`` 1)."""

    max_steps: int
    first_reach_back: float
    promote_at: float
    window: int
    step_back: float
    frontier_share: float
    episodes_per_replay: int = 1
    prepare_ahead: bool = False

    def check(self, source: str) -> None:
        check_positive(source, **{"expert_start.max_steps": self.max_steps, "expert_start.window": self.window,
                                  "expert_start.episodes_per_replay": self.episodes_per_replay})
        for name, value in (("first_reach_back", self.first_reach_back), ("promote_at", self.promote_at),
                            ("step_back", self.step_back)):
            if not 0.0 < value <= 1.0:
                raise ConfigError(f"{source}: 'expert_start.{name}' must be in (0, 1], got {value!r}")
        if not isinstance(self.prepare_ahead, bool):
            raise ConfigError(f"{source}: 'expert_start.prepare_ahead' must be true or false, got {self.prepare_ahead!r}")
        if self.prepare_ahead and self.episodes_per_replay > 1:
            raise ConfigError(f"{source}: 'expert_start.prepare_ahead' prepares one start at a time; "
                              f"set 'expert_start.episodes_per_replay' to 1 or 'prepare_ahead' to false")
        if not 0.0 <= self.frontier_share <= 1.0:
            raise ConfigError(f"{source}: 'expert_start.frontier_share' must be in [0, 1], got {self.frontier_share!r}")


@dataclass(frozen=True)
class Hyperparameters:
    """``config/<algo>_<task>.yaml`` (rl-zoo style): everything a training run is made of.

    ``env`` is merged over ``config/env.yaml`` (its keys are checked there); ``algo_kwargs`` go
    to the Stable-Baselines3 constructor (their names are checked against it by training).
    """

    n_timesteps: int
    n_envs: int
    normalize: NormalizeSettings
    env: Dict[str, Any]
    algo_kwargs: Dict[str, Any]
    # Fine-tuning (train.py --init-from) a model whose critic never learnt (e.g. DAgger's).
    critic_warmup: Optional[CriticWarmupSettings] = None
    # Training episodes start part-way along the scripted expert's trajectories (a reverse curriculum).
    expert_start: Optional[ExpertStartSettings] = None

    def check(self, source: str) -> None:
        check_positive(source, n_timesteps=self.n_timesteps, n_envs=self.n_envs)
        try:
            load_env_config(self.env)
        except ConfigError as error:
            raise ConfigError(f"{source}: 'env': {error}") from None

    def to_dict(self) -> Dict[str, Any]:
        """Plain JSON-able form (saved in a run's config.json; ``typed`` reads it back)."""
        return dataclasses.asdict(self)


LEARNING_RATE_SCHEDULES = ("constant", "cosine")


@dataclass(frozen=True)
class DaggerSettings:
    """The ``dagger`` section of ``config/dagger_<task>.yaml``."""

    rounds: int
    episodes: int
    epochs: int
    learning_rate: float
    expert_share_decay: float
    # "constant", or "cosine": each round's fit anneals the rate to zero, so the round ends on a
    # settled fit rather than wherever the last minibatches left it.
    learning_rate_schedule: str = "constant"
    # The gripper component's weight in the regression loss (the arm's six weigh 1 each): a
    # half-closed command drops a thin object or fails to hold a wide one.
    gripper_loss_weight: float = 1.0

    def check(self, source: str) -> None:
        check_positive(source, rounds=self.rounds, episodes=self.episodes, epochs=self.epochs,
                  learning_rate=self.learning_rate, gripper_loss_weight=self.gripper_loss_weight)
        if not 0.0 <= self.expert_share_decay <= 1.0:
            raise ConfigError(f"{source}: 'dagger.expert_share_decay' must be in [0, 1]")
        if self.learning_rate_schedule not in LEARNING_RATE_SCHEDULES:
            raise ConfigError(f"{source}: 'dagger.learning_rate_schedule' is {self.learning_rate_schedule!r}; "
                              f"use one of {', '.join(LEARNING_RATE_SCHEDULES)}")


@dataclass(frozen=True)
class DaggerConfig:
    """``config/dagger_<task>.yaml``: DAgger rounds, the env variant, the network that holds it."""

    dagger: DaggerSettings
    env: Dict[str, Any]
    algo_kwargs: Dict[str, Any]

    def check(self, source: str) -> None:
        try:
            load_env_config(self.env)
        except ConfigError as error:
            raise ConfigError(f"{source}: 'env': {error}") from None


def hyperparameter_path(path_or_name: str | Path) -> Path:
    """A hyperparameter file's path: ``path_or_name`` if it is a file, else ``config/<name>.yaml``
    (what a user sets: one file per algorithm and task), else ``config/recipes/<name>.yaml`` (the
    stages and variants of the experiments behind the shipped models)."""
    path = Path(path_or_name)
    if path.is_file():
        return path
    plain = config_path(str(path_or_name))
    recipe = config_path(f"recipes/{path_or_name}")
    return recipe if not plain.is_file() and recipe.is_file() else plain


def read_hyperparameter_file(path_or_name: str | Path, _seen: Tuple[Path, ...] = ()) -> Dict[str, Any]:
    """A hyperparameter file as a mapping, with its ``base`` (another file's name in ``config/``
    or a path) merged under it: a stage or variant states only what it changes.

    :raises ConfigError: a missing file, or files that build on each other in a circle.
    """
    path = hyperparameter_path(path_or_name).resolve()
    if path in _seen:
        raise ConfigError(f"{path.name}: 'base' leads back to itself ({' -> '.join(p.name for p in (*_seen, path))})")
    data = load_yaml(path)
    base = data.pop("base", None)
    if base is None:
        return data
    return deep_update(read_hyperparameter_file(str(base), (*_seen, path)), data, strict=False)
