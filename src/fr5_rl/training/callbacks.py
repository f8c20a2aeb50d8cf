"""Stable-Baselines3 callbacks of a training run: checkpoints, reward terms, gated evaluation, best model,
time to solve."""
from __future__ import annotations

import time
from collections import defaultdict
from pathlib import Path
from typing import Any, Dict, List

import numpy as np
import torch
from stable_baselines3.common.callbacks import BaseCallback, EvalCallback

try:
    from stable_baselines3.common.utils import FloatSchedule
except ImportError:  # stable-baselines3 < 2.6 (the Python 3.8 pin)
    from stable_baselines3.common.utils import get_schedule_fn as FloatSchedule

from ..deploy.bundle import save_model_dir, write_json_atomic

REPLAY_FILE = "replay_buffer.pkl"


def save_checkpoint(model, run_dir: Path, meta: Dict[str, Any]) -> None:
    """Model + normalisation stats (+ replay buffer for off-policy) as ``run_dir/checkpoints/latest``."""

    def write_replay_buffer(staging: Path) -> None:
        if getattr(model, "replay_buffer", None) is not None:
            model.save_replay_buffer(staging / REPLAY_FILE)

    save_model_dir(run_dir / "checkpoints" / "latest", model, model.get_vec_normalize_env(),
                   {**meta, "num_timesteps": int(model.num_timesteps)}, write_extra=write_replay_buffer)


class AtomicCheckpoint(BaseCallback):
    """Every ``freq`` steps, model + stats (+ replay buffer) replace ``checkpoints/latest`` at once.

    :param run_dir: the run directory.
    :param meta: the model's ``meta.json`` (``num_timesteps`` is added).
    :param freq: environment steps between checkpoints.
    """

    def __init__(self, run_dir: Path, meta: Dict[str, Any], freq: int) -> None:
        super().__init__()
        self.run_dir, self.meta = run_dir, meta
        self.freq = max(int(freq), 1)
        self._next = self.freq

    def _on_training_start(self) -> None:
        self._next = (self.num_timesteps // self.freq + 1) * self.freq

    def _on_step(self) -> bool:
        if self.num_timesteps >= self._next:
            save_checkpoint(self.model, self.run_dir, self.meta)
            self._next += self.freq
        return True


class RewardTermLogger(BaseCallback):
    """Per-episode sums of every reward part (``info['reward_*']``) and failure causes, into TensorBoard."""

    def __init__(self) -> None:
        super().__init__()
        self._running: List[Dict[str, float]] = []
        self._finished: Dict[str, List[float]] = defaultdict(list)
        self._failures: Dict[str, int] = defaultdict(int)
        self._episodes = 0

    def _on_step(self) -> bool:
        infos, dones = self.locals["infos"], self.locals["dones"]
        if not self._running:
            self._running = [defaultdict(float) for _ in infos]
        for index, (info, done) in enumerate(zip(infos, dones)):
            for key, value in info.items():
                if key.startswith("reward_"):
                    self._running[index][key] += float(value)
            if done:
                for key, value in self._running[index].items():
                    self._finished[key].append(value)
                self._running[index] = defaultdict(float)
                self._episodes += 1
                failure = info.get("failure")
                if failure:
                    self._failures[failure] += 1
        return True

    def _on_rollout_end(self) -> None:
        for key, values in self._finished.items():
            self.logger.record(f"reward_terms/{key[len('reward_'):]}", float(np.mean(values)))
        if self._episodes:
            for cause, count in self._failures.items():
                self.logger.record(f"failures/{cause}", count / self._episodes)
        self._finished.clear()
        self._failures.clear()
        self._episodes = 0


class SaveBest(BaseCallback):
    """On a new best evaluation: the model *with its statistics* into ``directory``."""

    def __init__(self, directory: Path, meta: Dict[str, Any]) -> None:
        super().__init__()
        self.directory, self.meta = directory, meta

    def _on_step(self) -> bool:
        save_model_dir(self.directory, self.model, self.model.get_vec_normalize_env(),
                       {**self.meta, "num_timesteps": int(self.model.num_timesteps)})
        return True


class GatedEvaluation(EvalCallback):
    """SB3's ``EvalCallback`` that skips an evaluation while the training episodes finished
    since the previous one succeeded less than ``min_training_success`` of the time.

    An evaluation of 40 episodes costs as much as several thousand training steps; early in a
    run, when no training episode succeeds yet, it cannot reach the target. The training episodes
    act with exploration noise and the evaluation deterministically, so a gate well below the
    target delays no evaluation that would have passed: time to solve is measured the same way,
    only without the evaluations that could not count.

    :param min_training_success: 0..1; 0 evaluates every ``eval_freq`` calls (plain EvalCallback).
    """

    def __init__(self, *args: Any, min_training_success: float = 0.0, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        if not 0.0 <= min_training_success <= 1.0:
            raise ValueError(f"min_training_success must be in [0, 1], got {min_training_success}")
        self.min_training_success = float(min_training_success)
        self.skipped = 0
        self._episodes = self._successes = 0

    def _on_step(self) -> bool:
        if self.min_training_success > 0.0:
            infos = self.locals["infos"]
            for index in np.flatnonzero(self.locals["dones"]):  # episode ends only: this runs every step
                self._episodes += 1
                self._successes += bool(infos[index].get("is_success", False))
            if self.eval_freq > 0 and self.n_calls % self.eval_freq == 0:
                rate = self._successes / self._episodes if self._episodes else 0.0
                self._episodes = self._successes = 0
                if rate < self.min_training_success:
                    self.skipped += 1
                    return True
        return super()._on_step()


class SolveTimer(BaseCallback):
    """After each evaluation: records the success history, and when the success rate first
    reaches ``target`` (time to solve, with the model saved as ``solved/``); may stop there.

    :param t_start: wall-clock start of the run (s since the epoch), earlier sessions included.
    :param target: evaluation success rate that counts as solved (0..1).
    :param stop_at_success: end training once solved.
    """

    def __init__(self, run_dir: Path, meta: Dict[str, Any], summary: Dict[str, Any], t_start: float,
                 target: float, stop_at_success: bool) -> None:
        super().__init__()
        self.run_dir, self.meta, self.summary = run_dir, meta, summary
        self.t_start, self.target, self.stop_at_success = t_start, target, stop_at_success

    def _on_step(self) -> bool:
        evaluator, summary = self.parent, self.summary
        rate = float(np.mean(evaluator._is_success_buffer)) if evaluator._is_success_buffer else 0.0
        wall = round(time.time() - self.t_start, 1)
        summary.setdefault("eval_history", []).append(
            {"timesteps": int(self.num_timesteps), "wall_s": wall, "success_rate": rate})
        if rate >= self.target and "time_to_solve_s" not in summary:
            summary["time_to_solve_s"] = wall
            summary["timesteps_to_solve"] = int(self.num_timesteps)
            save_model_dir(self.run_dir / "solved", self.model, self.model.get_vec_normalize_env(),
                           {**self.meta, "num_timesteps": int(self.num_timesteps)})
        write_json_atomic(self.run_dir / "summary.json", summary)
        return not (self.stop_at_success and "time_to_solve_s" in summary)


class CriticWarmup(BaseCallback):
    """For the first ``steps`` environment steps of a fine-tuning run, only the critic learns.

    A model imitated from an expert (DAgger) has a trained actor and an untrained value network.
    PPO's first updates would follow advantages computed from that untrained critic, noise that
    can undo the imitation before reward has had a say. Holding the actor's parameters
    (``requires_grad`` off: Adam skips parameters without gradients) until the critic has fitted
    a few rollouts avoids that. Updates on rollouts that end within ``steps`` train only the
    critic; later ones train both, at the run's own learning rate again.

    :param steps: environment steps of critic-only training.
    :param learning_rate: the (constant) learning rate while the actor is held: a fresh critic
        needs larger steps than the fine-tuning of a good actor.
    """

    def __init__(self, steps: int, learning_rate: float) -> None:
        super().__init__()
        self.steps, self.learning_rate = int(steps), float(learning_rate)
        self.held = False

    def actor_parameters(self):
        policy = self.model.policy
        parts = [policy.mlp_extractor.policy_net, policy.action_net]
        parameters = [p for part in parts for p in part.parameters()]
        if isinstance(getattr(policy, "log_std", None), torch.nn.Parameter):
            parameters.append(policy.log_std)
        return parameters

    def _set_held(self, held: bool) -> None:
        for parameter in self.actor_parameters():
            parameter.requires_grad_(not held)
        # Schedules as SB3 builds them (picklable: checkpoints save them); after the warm-up, the
        # run's own learning rate, which is the model's even when resumed from a warm-up checkpoint.
        self.model.lr_schedule = FloatSchedule(self.learning_rate if held else self.model.learning_rate)
        self.held = held

    def _on_training_start(self) -> None:
        if self.num_timesteps < self.steps:
            self._set_held(True)

    def _on_rollout_end(self) -> None:
        if self.held and self.num_timesteps > self.steps:  # this rollout's update is past the warm-up
            self._set_held(False)
        self.logger.record("train/actor_held", float(self.held))

    def _on_step(self) -> bool:
        return True
