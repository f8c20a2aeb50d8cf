"""DAgger from the scripted expert: what ``rosrun fr5_rl imitate.py`` runs.

Behaviour cloning alone copies the expert on the states the expert visits, and drifts once
the learner's own small errors take it elsewhere. DAgger (Ross et al., 2011) fixes that: each
round the learner drives, the expert labels every state the learner reached, the labels join
the data set, and the learner is re-fitted on all of it. The expert is privileged (it reads the
simulator's ground truth), the learner sees only the observation the ROS node can build, so
observation noise, latency and mass/friction randomisation can be on while it learns.

The result is an ordinary model directory (SB3 PPO ``model.zip`` whose actor holds the learned
weights, ``vecnormalize.pkl`` with the data set's statistics, ``meta.json``), so evaluate.py,
export_onnx.py and the ROS node take it like any trained model.
"""
from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from ..config import ConfigError, typed
from ..deploy.bundle import build_meta, machine_description, save_model_dir, write_json_atomic
from .hyperparameters import DaggerConfig, hyperparameter_path, read_hyperparameter_file
from .run_settings import DaggerRun
from .train import EVAL_SEED_OFFSET


STATE_DIR = "dagger_state"  # in the run directory: what ``--resume`` continues from
STATE_FILE = "state.json"


class DaggerCheckpoint:
    """A DAgger run's state between rounds, in ``run_dir/dagger_state/``: the data set so far, the
    actor's weights, the history and the random generator's state.

    Written after each round's new data joined the set; ``state.json`` goes last and names the
    other two files, so a run killed mid-write resumes from the round before.

    :param run_dir: the run directory.
    """

    def __init__(self, run_dir: Path) -> None:
        self.directory = Path(run_dir) / STATE_DIR

    def save(self, next_round: int, observations: np.ndarray, labels: np.ndarray, model: Optional[Any],
             history: List[Dict[str, Any]], best: Tuple[float, Optional[int]], rng: np.random.Generator,
             elapsed_s: float, identity: Dict[str, Any], finished: Optional[int] = None) -> None:
        """Record what round ``next_round`` starts from; ``finished``: the run's last round, fitted
        and judged, whose learner has not rolled out (a resume with more rounds does that first)."""
        import torch

        self.directory.mkdir(parents=True, exist_ok=True)
        data_name = f"data_{next_round}.npz"
        weights_name = f"actor_{next_round}.pt" if model is not None else None  # none before round 1
        with open(self.directory / (data_name + ".tmp"), "wb") as handle:
            np.savez(handle, observations=observations, labels=labels)
        (self.directory / (data_name + ".tmp")).replace(self.directory / data_name)
        if weights_name:
            torch.save(model.policy.state_dict(), self.directory / (weights_name + ".tmp"))
            (self.directory / (weights_name + ".tmp")).replace(self.directory / weights_name)
        write_json_atomic(self.directory / STATE_FILE, {
            "next_round": next_round, "data": data_name, "actor": weights_name, "history": history,
            "best_score": best[0], "best_round": best[1], "rng": rng.bit_generator.state,
            "elapsed_s": elapsed_s, "run": identity, "finished": finished})
        for old in self.directory.glob("*_*.*"):
            if old.name not in (data_name, weights_name):
                old.unlink()

    def exists(self) -> bool:
        """Whether a round finished, so that the run can resume."""
        return (self.directory / STATE_FILE).is_file()

    def load(self, identity: Dict[str, Any]) -> Dict[str, Any]:
        """The saved state, with ``observations``, ``labels`` and ``actor`` (a state dict) loaded.

        :raises ConfigError: nothing to resume, or the run began with other settings.
        """
        import json

        import torch

        path = self.directory / STATE_FILE
        if not path.is_file():
            raise ConfigError(f"{self.directory.parent} has no finished DAgger round to resume ({path} is missing); "
                              "start it again without --resume")
        state = json.loads(path.read_text())
        differing = {key: (state["run"].get(key), value) for key, value in identity.items()
                     if state["run"].get(key) != value}
        if differing:
            raise ConfigError("this run began with other settings; resume it with the ones it began with: "
                              + ", ".join(f"{key} {was!r} (given {now!r})" for key, (was, now) in differing.items()))
        with np.load(self.directory / state["data"]) as data:
            state["observations"], state["labels"] = data["observations"], data["labels"]
        if state["actor"]:
            state["actor"] = torch.load(self.directory / state["actor"], map_location="cpu")
        return state


def rollouts(env, expert, learner, episodes: int, seed: int, expert_probability: float,
             rng: np.random.Generator) -> Tuple[np.ndarray, np.ndarray, float]:
    """Run ``episodes`` episodes; return (observations, expert labels, learner-driven success).

    Each step the expert's action is executed with ``expert_probability``, the learner's
    otherwise; every visited observation is labelled with the expert's action.
    """
    observations: List[np.ndarray] = []
    labels: List[np.ndarray] = []
    successes = 0
    for episode in range(episodes):
        obs, _ = env.reset(seed=seed + episode)
        expert.reset()
        done, info = False, {}
        while not done:
            label = expert.act(obs)
            observations.append(obs.copy())
            labels.append(label)
            use_expert = learner is None or rng.random() < expert_probability
            action = label if use_expert else learner(obs)
            obs, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
        successes += bool(info.get("is_success"))
    return np.asarray(observations, np.float32), np.asarray(labels, np.float32), successes / max(episodes, 1)


class Normaliser:
    """Observation statistics in the form SB3's VecNormalize keeps them."""

    def __init__(self, observations: np.ndarray, clip: float = 10.0, epsilon: float = 1e-8) -> None:
        self.mean = observations.mean(axis=0).astype(np.float64)
        self.var = observations.var(axis=0).astype(np.float64)
        self.count = float(len(observations))
        self.clip, self.epsilon = clip, epsilon

    def __call__(self, observations: np.ndarray) -> np.ndarray:
        return np.clip((observations - self.mean) / np.sqrt(self.var + self.epsilon), -self.clip, self.clip)


def learning_rate_at(schedule: str, learning_rate: float, progress: float) -> float:
    """The fit's rate ``progress`` (0 to 1) of the way through: ``learning_rate`` throughout
    (``"constant"``), or annealed from it to zero along a half cosine (``"cosine"``)."""
    if schedule == "cosine":
        return 0.5 * learning_rate * (1.0 + math.cos(math.pi * progress))
    return learning_rate


def fit(model, normaliser: Normaliser, observations: np.ndarray, labels: np.ndarray, epochs: int,
        batch_size: int = 256, learning_rate: float = 1e-3, seed: int = 0, schedule: str = "constant",
        gripper_loss_weight: float = 1.0) -> float:
    """Regress the PPO actor's mean action onto the expert labels (weighted MSE).

    :param schedule: ``"constant"`` or ``"cosine"`` (the rate annealed to zero over the epochs).
    :param gripper_loss_weight: the last action component's weight; the arm's weigh 1 each.
    :return: the mean loss over the last epoch.
    """
    import torch

    torch.manual_seed(seed)
    policy = model.policy
    parameters = list(policy.mlp_extractor.policy_net.parameters()) + list(policy.action_net.parameters())
    optimiser = torch.optim.Adam(parameters, lr=learning_rate)
    x = torch.as_tensor(normaliser(observations), dtype=torch.float32)
    y = torch.as_tensor(np.clip(labels, -1.0, 1.0), dtype=torch.float32)
    weights = torch.ones(y.shape[1], dtype=torch.float32)
    weights[-1] = gripper_loss_weight
    weights = weights / weights.mean()
    generator = torch.Generator().manual_seed(seed)
    batches_per_epoch = (len(x) + batch_size - 1) // batch_size
    total_batches = max(epochs * batches_per_epoch, 1)
    batch_number = 0
    epoch_loss = float("nan")
    for _ in range(epochs):
        order = torch.randperm(len(x), generator=generator)
        loss_sum = 0.0
        for start in range(0, len(x), batch_size):
            for group in optimiser.param_groups:
                group["lr"] = learning_rate_at(schedule, learning_rate, batch_number / total_batches)
            index = order[start:start + batch_size]
            latent = policy.mlp_extractor.forward_actor(policy.extract_features(x[index], policy.pi_features_extractor))
            loss = torch.mean(weights * (policy.action_net(latent) - y[index]) ** 2)
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            loss_sum += float(loss.detach()) * len(index)
            batch_number += 1
        epoch_loss = loss_sum / max(len(x), 1)
    return epoch_loss


class ActorSnapshot:
    """The learner's deterministic actor as a function (raw observation -> action in [-1, 1]),
    detached from its PPO model so that it pickles into the rollout workers: the actor's layers and
    the observation statistics (MlpPolicy's feature extractor only flattens a 1-D observation)."""

    def __init__(self, model, normaliser: Normaliser) -> None:
        import copy

        self.policy_net = copy.deepcopy(model.policy.mlp_extractor.policy_net)
        self.action_net = copy.deepcopy(model.policy.action_net)
        self.normaliser = normaliser

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        import torch

        with torch.no_grad():
            x = torch.as_tensor(self.normaliser(observation[None]), dtype=torch.float32)
            return np.clip(self.action_net(self.policy_net(x)).numpy()[0], -1.0, 1.0)


def make_learner(model, normaliser: Normaliser) -> ActorSnapshot:
    """Deterministic actor as a function: raw observation -> action in [-1, 1]."""
    return ActorSnapshot(model, normaliser)


_worker_envs: Dict[str, Any] = {}


def _start_worker(task: str, overrides: Dict[str, Dict[str, Any]]) -> None:
    """A rollout worker's set-up: one environment per name (the training one is ``"training"``)."""
    import torch

    from ..envs import FR5Env

    torch.set_num_threads(1)
    for name, config in overrides.items():
        _worker_envs[name] = FR5Env(task=task, config=config)


def _worker_rollouts(first_episode: int, episodes: int, seed: int, expert_probability: float,
                     rng_seed: Sequence[int], learner: Optional[ActorSnapshot]):
    from ..expert import ScriptedExpert

    env = _worker_envs["training"]
    rng = np.random.default_rng(list(rng_seed))
    return rollouts(env, ScriptedExpert(env), learner, episodes, seed + first_episode, expert_probability, rng)


def _worker_evaluate(env_name: str, first_episode: int, episodes: int, seed: int, learner: ActorSnapshot) -> int:
    return round(evaluate(_worker_envs[env_name], learner, episodes, seed + first_episode) * episodes)


def _chunks(episodes: int, count: int) -> List[Tuple[int, int]]:
    """``episodes`` split into at most ``count`` contiguous (first, length) runs, as even as can be."""
    count = max(1, min(count, episodes))
    base, extra = divmod(episodes, count)
    chunks, first = [], 0
    for index in range(count):
        length = base + (1 if index < extra else 0)
        chunks.append((first, length))
        first += length
    return chunks


class RolloutWorkers:
    """DAgger's episodes spread over worker processes, each with its own environments.

    The episodes keep their seeds (``seed + episode``) whatever the count; each worker's share of
    expert steps draws from its own generator, seeded from the run's, so a run's labels depend on
    the worker count but are reproducible for a given one. With one worker nothing is started:
    the caller runs the serial functions (:func:`rollouts`, :func:`evaluate`), as before workers.

    :param count: worker processes (at least 2 to start any).
    :param task: the task of every environment.
    :param overrides: environment name -> its configuration overrides; ``"training"`` is the
        one DAgger rolls out in, the others are evaluated in.
    """

    def __init__(self, count: int, task: str, overrides: Dict[str, Dict[str, Any]]) -> None:
        import multiprocessing

        self.count = count
        self._pool = multiprocessing.get_context("forkserver").Pool(count, _start_worker, (task, overrides))

    def rollouts(self, learner: Optional[ActorSnapshot], episodes: int, seed: int, expert_probability: float,
                 rng: np.random.Generator) -> Tuple[np.ndarray, np.ndarray, float]:
        """As :func:`rollouts`, over the workers."""
        base_seed = int(rng.integers(2 ** 31))
        jobs = [(first, length, seed, expert_probability, (base_seed, index), learner)
                for index, (first, length) in enumerate(_chunks(episodes, self.count))]
        parts = self._pool.starmap(_worker_rollouts, jobs)
        observations = np.concatenate([part[0] for part in parts])
        labels = np.concatenate([part[1] for part in parts])
        successes = sum(rate * length for (_, _, rate), (_, length, *_) in zip(parts, jobs))
        return observations, labels, successes / max(episodes, 1)

    def evaluate(self, env_name: str, learner: ActorSnapshot, episodes: int, seed: int) -> float:
        """As :func:`evaluate`, in the workers' environment ``env_name``."""
        jobs = [(env_name, first, length, seed, learner) for first, length in _chunks(episodes, self.count)]
        return sum(self._pool.starmap(_worker_evaluate, jobs)) / max(episodes, 1)

    def close(self) -> None:
        self._pool.close()
        self._pool.join()


def build_model_and_stats(task: str, env_overrides: Dict[str, Any], algo_kwargs: Dict[str, Any],
                          normaliser: Normaliser, seed: int):
    """An SB3 PPO model of the configured architecture and a VecNormalize holding our stats."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from ..envs import FR5Env

    venv = VecNormalize(DummyVecEnv([lambda: FR5Env(task=task, config=env_overrides)]), norm_obs=True,
                        norm_reward=False, clip_obs=normaliser.clip, epsilon=normaliser.epsilon)
    kwargs = dict(algo_kwargs)
    kwargs.pop("policy", None)
    model = PPO("MlpPolicy", venv, seed=seed, device="cpu", verbose=0, **kwargs)
    return model, venv


def sync_stats(venv, normaliser: Normaliser) -> None:
    venv.obs_rms.mean, venv.obs_rms.var, venv.obs_rms.count = normaliser.mean, normaliser.var, normaliser.count
    venv.training = False


def evaluate(env, learner, episodes: int, seed: int) -> float:
    successes = 0
    for episode in range(episodes):
        obs, _ = env.reset(seed=seed + episode)
        done, info = False, {}
        while not done:
            obs, _, terminated, truncated, info = env.step(learner(obs))
            done = terminated or truncated
        successes += bool(info.get("is_success"))
    return successes / max(episodes, 1)


def run_dagger(run: DaggerRun) -> int:
    """Run DAgger with ``run``'s settings (the command line's: :mod:`fr5_rl.cli.imitate`); returns 0.

    :raises ConfigError: the DAgger file is malformed; ``run.resume`` finds no round to resume from,
        or a run begun with other settings.
    """
    import torch

    from ..envs import FR5Env
    from ..expert import ScriptedExpert

    t_start = time.time()
    torch.set_num_threads(run.torch_threads)
    name = run.hyperparams or f"dagger_{run.task}"
    # A file in config/ or config/recipes/, with the ``base`` it builds on.
    config = typed(DaggerConfig, read_hyperparameter_file(name), str(hyperparameter_path(name).name))
    dagger = config.dagger
    rounds = run.rounds if run.rounds is not None else dagger.rounds
    episodes = run.episodes or dagger.episodes
    epochs = run.epochs or dagger.epochs
    env_overrides = {**config.env, "robot": run.robot} if run.robot else config.env
    run_dir = run.run_dir or Path("runs") / f"{run.task}_dagger_{time.strftime('%Y%m%d-%H%M%S')}"
    run_dir.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(run.seed)

    env = FR5Env(task=run.task, config=env_overrides)
    # Each round is judged on the task as registered and, when training randomises, also on
    # the training variant; the best round is the one with the highest sum of both.
    # "The task" keeps the file's definition of it (objects, observation) but not its randomisation,
    # so the learner's observation has the same shape in both.
    plain_overrides = {key: value for key, value in env_overrides.items() if key != "randomisation"}
    eval_envs = {"task": FR5Env(task=run.task, config=plain_overrides)}
    if env_overrides:
        eval_envs["training_env"] = FR5Env(task=run.task, config=env_overrides)
    expert = ScriptedExpert(env)
    workers = None
    if run.workers > 1:
        workers = RolloutWorkers(run.workers, run.task, {"training": env_overrides, "task": plain_overrides,
                                                         **({"training_env": env_overrides} if env_overrides else {})})

    def roll_out(learner, round_seed: int, expert_probability: float):
        if workers is None:
            return rollouts(env, expert, learner, episodes, round_seed, expert_probability, rng)
        return workers.rollouts(learner, episodes, round_seed, expert_probability, rng)

    checkpoint = DaggerCheckpoint(run_dir)
    # What must match for a resumed run to continue the same one (the rounds may grow).
    identity = {"task": run.task, "hyperparams": name, "seed": run.seed, "episodes": episodes, "epochs": epochs,
                "workers": run.workers, "robot": env.cfg.robot}
    model = venv = None
    saved_actor = None
    # A round fitted and judged whose learner has not rolled out yet: the last round of a run that
    # finished, resumed with more rounds.
    fitted_round = None
    if run.resume:
        state = checkpoint.load(identity)
        observations, labels, history = state["observations"], state["labels"], state["history"]
        best = (state["best_score"], state["best_round"])
        rng.bit_generator.state = state["rng"]
        first_round, saved_actor, fitted_round = state["next_round"], state["actor"], state.get("finished")
        t_start = time.time() - state["elapsed_s"]
        print(f"resuming {run_dir} at round {first_round} ({len(observations)} samples)")
    else:
        observations, labels, expert_success = roll_out(None, run.seed, 1.0)
        print(f"round 0: expert demonstrations, {len(observations)} samples, expert success {expert_success:.0%}")
        history = [{"round": 0, "samples": len(observations), "driver_success": expert_success,
                    "wall_s": round(time.time() - t_start, 1)}]
        best = (-1.0, None)
        first_round = 1
        checkpoint.save(first_round, observations, labels, None, history, best, rng,
                        time.time() - t_start, identity)
    try:
        for round_index in range(first_round, rounds + 1):
            normaliser = Normaliser(observations)
            if model is None:
                model, venv = build_model_and_stats(run.task, env_overrides, config.algo_kwargs, normaliser, run.seed)
                if saved_actor:
                    model.policy.load_state_dict(saved_actor)
            if round_index != fitted_round:
                loss = fit(model, normaliser, observations, labels, epochs, seed=run.seed + round_index,
                           learning_rate=dagger.learning_rate, schedule=dagger.learning_rate_schedule,
                           gripper_loss_weight=dagger.gripper_loss_weight)
                learner = make_learner(model, normaliser)
                if workers is None:
                    rates = {name: evaluate(e, learner, run.eval_episodes, run.seed + EVAL_SEED_OFFSET)
                             for name, e in eval_envs.items()}
                else:
                    rates = {name: workers.evaluate(name, learner, run.eval_episodes, run.seed + EVAL_SEED_OFFSET)
                             for name in eval_envs}
                success = sum(rates.values()) / len(rates)
                sync_stats(venv, normaliser)
                meta = build_meta(run.task, "ppo", env_overrides, env.cfg, env.observation_space.shape[0],
                                  env.action_space.shape[0], env.control_dt, run.seed, trained_by="dagger",
                                  num_timesteps=int(len(observations)), dagger_round=round_index)
                if success > best[0]:
                    best = (success, round_index)
                    save_model_dir(run_dir / "best", model, venv, meta)
                save_model_dir(run_dir / "final", model, venv, meta)
                history.append({"round": round_index, "samples": int(len(observations)), "fit_loss": loss,
                                "eval_success": rates["task"], "eval_success_training_env": rates.get("training_env"),
                                "wall_s": round(time.time() - t_start, 1)})
                print(f"round {round_index}: {len(observations)} samples, loss {loss:.4f}, learner success "
                      + ", ".join(f"{rate:.0%} ({name})" for name, rate in rates.items())
                      + f" on {run.eval_episodes} episodes")
                write_json_atomic(run_dir / "summary.json", {
                    "task": run.task, "method": "dagger", "history": history, "best_round": best[1],
                    "best_score": best[0], "wall_time_s": round(time.time() - t_start, 1),
                    "machine": machine_description(), "seed": run.seed})
            else:
                learner = make_learner(model, normaliser)
            if round_index == rounds:
                # Finished: a resume with more rounds rolls this learner out first.
                checkpoint.save(round_index, observations, labels, model, history, best, rng,
                                time.time() - t_start, identity, finished=round_index)
                break
            # The learner drives (with a decaying share of expert steps), the expert labels.
            beta = dagger.expert_share_decay ** round_index
            new_obs, new_labels, _ = roll_out(learner, run.seed + 1000 * round_index, beta)
            observations = np.concatenate([observations, new_obs])
            labels = np.concatenate([labels, new_labels])
            checkpoint.save(round_index + 1, observations, labels, model, history, best, rng,
                            time.time() - t_start, identity)
    finally:
        if workers is not None:
            workers.close()
        env.close()
        for e in eval_envs.values():
            e.close()
    print(f"best round {best[1]}: success {best[0]:.0%}; run directory {run_dir}")
    return 0
