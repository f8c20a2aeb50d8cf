"""Training an FR5 policy with Stable-Baselines3: what ``rosrun fr5_rl train.py`` runs.

A run directory holds ``config.json`` (everything needed to resume), ``checkpoints/latest``
(model + normalisation stats, replaced atomically every ``--checkpoint-freq`` steps),
``best/`` (best evaluation so far), ``final/``, TensorBoard logs in ``tb/``, evaluation curves
in ``eval/evaluations.npz`` and ``summary.json`` (steps, wall time, time to solve, machine).

The run's settings are a :class:`~fr5_rl.training.run_settings.TrainRun`.
"""
from __future__ import annotations

import copy
import dataclasses
import json
import os
import shutil
import sys
import time
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple


from ..config import DEFAULT_ROBOT, ConfigError, typed
from ..deploy.bundle import (MODEL_FILE, STATS_FILE, ModelFilesError, algorithm_class, build_meta,
                              check_files_present, check_sb3_zip, damaged, machine_description, read_meta,
                              recover_model_dir, save_model_dir, write_json_atomic)
from .algorithms import check_hyperparameters, hyperparameter_source, load_hyperparameters
from .hyperparameters import ExpertStartSettings, Hyperparameters
from .run_settings import CONFIG_FILE, FIXED_ON_RESUME, TrainRun, read_run_config

EVAL_SEED_OFFSET = 10_000  # evaluation seeds never overlap training seeds


def make_env_factory(task: str, env_overrides: Dict[str, Any], seed: int, rank: int,
                     monitor_dir: Optional[Path], expert_start: Optional[ExpertStartSettings] = None):
    """A picklable constructor for one (Monitor-wrapped) environment of a vectorised set.

    :param expert_start: episodes start part-way along the scripted expert's trajectories
        (:class:`~fr5_rl.training.curriculum.ExpertStartWrapper`, inside the Monitor, so the
        episode statistics are the policy's own); None: plain resets.
    """

    def _init():
        import multiprocessing
        import signal

        if multiprocessing.parent_process() is not None:
            # SubprocVecEnv worker: Ctrl-C reaches the whole process group, but handling it is
            # the trainer's job (save a checkpoint, then close the workers).
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        import fr5_rl  # noqa: F401  (registers the environments in the worker)
        from stable_baselines3.common.monitor import Monitor

        from ..envs import FR5Env

        env = FR5Env(task=task, config=env_overrides)
        if expert_start is not None:
            from .curriculum import ExpertStartWrapper

            spare = FR5Env(task=task, config=env_overrides) if expert_start.prepare_ahead else None
            env = ExpertStartWrapper(env, expert_start.max_steps, frontier_share=expert_start.frontier_share,
                                     episodes_per_replay=expert_start.episodes_per_replay, spare=spare)
        filename = str(monitor_dir / f"env{rank}") if monitor_dir is not None else None
        # Append when resuming; a new file needs its header (SB3 writes it only when overriding).
        fresh = filename is None or not Path(f"{filename}.{Monitor.EXT}").is_file()
        env = Monitor(env, filename=filename, info_keywords=("is_success", "failure"),
                      override_existing=fresh)
        env.reset(seed=seed + rank)
        env.action_space.seed(seed + rank)
        return env

    return _init


def available_cores() -> int:
    """CPU cores this process may run on (its affinity mask, not the machine's count)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def make_vec_env(task: str, env_overrides: Dict[str, Any], n_envs: int, seed: int,
                 monitor_dir: Optional[Path], subprocess: bool, start_method: str = "forkserver",
                 processes: Optional[int] = None, expert_start: Optional[ExpertStartSettings] = None):
    """``n_envs`` environments, stepped on ``processes`` cores when ``subprocess``.

    The environments are cut into one chunk per process: this process steps the first chunk (one
    environment lighter when ``expert_start.prepare_ahead``), worker processes step the others
    (:class:`~fr5_rl.training.vec_env.ChunkedSubprocVecEnv`).
    Environment ``rank`` is seeded ``seed + rank`` wherever it runs, so the layout changes speed,
    never results.

    :param start_method: ``forkserver`` (train.py), or ``spawn`` inside a Ray worker, where forking
        a process that runs Ray's threads can hang.
    :param processes: processes stepping environments, this one included; default one per
        available core, at most ``n_envs``. One means a plain ``DummyVecEnv``.
    :param expert_start: see :func:`make_env_factory` (None: plain resets).
    """
    from stable_baselines3.common.vec_env import DummyVecEnv

    from .vec_env import ChunkedSubprocVecEnv

    factories = [make_env_factory(task, env_overrides, seed, rank, monitor_dir, expert_start)
                 for rank in range(n_envs)]
    processes = min(processes or available_cores(), n_envs) if subprocess else 1
    if processes <= 1:
        return DummyVecEnv(factories)
    # Starts prepared ahead: a worker prepares its spares while the trainer runs the policy and
    # the updates, the trainer's own chunk only while it waits for a worker. One environment
    # fewer in the trainer's chunk gives it that wait: grasp from reward, 16 environments on two
    # cores, took 0.91x the time of 8 and 8 (docs/experiments.md).
    trainer_fewer = 1 if expert_start is not None and expert_start.prepare_ahead else 0
    return ChunkedSubprocVecEnv(factories, processes, start_method=start_method, trainer_fewer=trainer_fewer)


def build_callbacks(run: TrainRun, run_dir: Path, eval_env, meta: Dict[str, Any], t_start: float,
                    summary: Dict[str, Any]):
    """Checkpointing, evaluation (best model with stats), reward-term logging, time-to-solve:
    the callback list, and its evaluation callback (which counts the evaluations it skipped)."""
    from stable_baselines3.common.callbacks import CallbackList

    from .callbacks import AtomicCheckpoint, GatedEvaluation, RewardTermLogger, SaveBest, SolveTimer

    eval_every = max(run.eval_freq // run.n_envs, 1)
    evaluation = GatedEvaluation(
        eval_env, n_eval_episodes=run.eval_episodes, eval_freq=eval_every, deterministic=True,
        log_path=str(run_dir / "eval"), best_model_save_path=None, callback_on_new_best=SaveBest(run_dir / "best", meta),
        callback_after_eval=SolveTimer(run_dir, meta, summary, t_start, run.target_success, run.stop_at_success),
        verbose=0, min_training_success=float(run.eval_min_training_success),
    )
    return CallbackList([AtomicCheckpoint(run_dir, meta, run.checkpoint_freq), RewardTermLogger(), evaluation]), evaluation


def close_vec_env(venv, interrupted: bool) -> None:
    """Close a (VecNormalize-wrapped) vectorised env; after Ctrl-C, stop subprocess workers.

    Ctrl-C can land while the trainer is collecting step results from the workers, half of
    them read; a polite close would then wait for answers that never come. The workers hold
    nothing worth saving, so they are terminated instead.
    """
    inner = getattr(venv, "venv", venv)
    if interrupted and hasattr(inner, "processes"):  # SubprocVecEnv or ChunkedSubprocVecEnv
        for process in inner.processes:
            process.terminate()
        for process in inner.processes:
            process.join(timeout=5)
        inner.closed = True
        return
    venv.close()


def write_run_config(run_dir: Path, run: TrainRun, hyper: Hyperparameters, **extra: Any) -> None:
    """``config.json``: everything ``--resume`` needs to continue the run as it was started
    (:meth:`TrainRun.saved_config`)."""
    write_json_atomic(run_dir / "config.json", run.saved_config(hyper.to_dict(), **extra))


def initialise_from(model_dir: Path, task: str, algo: str, venv, meta: Dict[str, Any], run_dir: Path,
                    algo_kwargs: Dict[str, Any]):
    """A trained model and its VecNormalize statistics, bound to this run's environments, with
    this run's algorithm settings (learning rate, n_steps, clip range, ...) in place of the ones it
    was saved with; its network (``policy``, ``policy_kwargs``) is the saved one.

    :raises ConfigError: the model is for another task, algorithm or observation/action size.
    :raises ModelFilesError: its files are missing or damaged.
    """
    source = read_meta(model_dir)
    added = added_observation_blocks(source, meta)
    for key in ("task", "algo", "observation_size", "action_size"):
        if source.get(key) != meta.get(key) and not (key == "observation_size" and added):
            raise ConfigError(f"--init-from {model_dir}: its {key} is {source.get(key)!r}, this run's is "
                              f"{meta.get(key)!r}; start from a model of the same task and algorithm")
    check_files_present(model_dir, "torch")
    settings = {key: value for key, value in algo_kwargs.items() if key not in ("policy", "policy_kwargs")}
    if added:
        model, venv = load_widened(model_dir, algorithm_class(algo), venv, added, int(meta["seed"]),
                                   tensorboard_log=str(run_dir / "tb"), **settings)
    else:
        model, venv = load_trained(model_dir, algorithm_class(algo), venv, tensorboard_log=str(run_dir / "tb"),
                                   **settings)
    venv.training = True  # the statistics keep adapting to the new randomisation
    return model, venv


def added_observation_blocks(source: Dict[str, Any], meta: Dict[str, Any]) -> List[Tuple[int, int]]:
    """The observation values this run has and the ``--init-from`` model lacks, the rest of the
    layout being the same: more previous actions (``observation.previous_actions``) and a
    joint-step hint (``observation.joint_step_hint``) it was trained without.

    :return: ``(index, count)`` blocks: ``count`` new values go before value ``index`` of the
        model's observation (its length: at the end); empty when nothing is added or the
        layouts differ otherwise.
    """
    from ..observation import ARM_ACTION_SIZE

    had_cfg = (source.get("env_config") or {}).get("observation") or {}
    has_cfg = meta["env_config"]["observation"]
    try:
        had, hint_had = int(had_cfg["previous_actions"]), had_cfg["joint_step_hint"] is not None
    except KeyError as missing:
        raise ConfigError(f"--init-from: the model's meta.json has no observation.{missing.args[0]}: it comes from an "
                          "older fr5_rl; train anew, or use the fr5_rl it was trained with") from None
    has, hint_has = int(has_cfg["previous_actions"]), has_cfg["joint_step_hint"] is not None
    if has < had or (hint_had and not hint_has):
        return []
    old_size = int(source.get("observation_size") or 0)
    blocks = []
    if has > had:  # after the old previous actions, before the hint
        blocks.append((old_size - (ARM_ACTION_SIZE if hint_had else 0), ARM_ACTION_SIZE * (has - had)))
    if hint_has and not hint_had:  # the hint comes last
        blocks.append((old_size, ARM_ACTION_SIZE))
    added = sum(count for _, count in blocks)
    return blocks if blocks and old_size + added == meta.get("observation_size") else []


def load_widened(model_dir: Path, algo_cls, venv, blocks: Sequence[Tuple[int, int]], seed: int,
                 **model_kwargs: Any):
    """The model in ``model_dir``, its inputs widened by new observation values (more previous
    actions, a joint-step hint), acting exactly as it did: every weight it had is copied, and
    the weights of the new inputs start at zero. Its VecNormalize statistics are widened with
    mean 0 and variance 1 for the new values, which then adapt like the others.

    :param blocks: ``(index, count)``: ``count`` new values before value ``index`` of the old
        observation (:func:`added_observation_blocks`).
    :param model_kwargs: this run's algorithm settings (the network is the saved one).
    :raises ModelFilesError: a damaged ``model.zip`` or ``vecnormalize.pkl``.
    """
    import numpy as np
    import torch
    from stable_baselines3.common.vec_env import VecNormalize

    from ..deploy.policy import load_normalizer

    try:
        stats = load_normalizer(model_dir)
        check_sb3_zip(model_dir / MODEL_FILE)
        try:
            source = algo_cls.load(model_dir / MODEL_FILE, device="cpu")
        except Exception as error:
            raise damaged(model_dir / MODEL_FILE, error, f"a Stable-Baselines3 {algo_cls.__name__} model") from None
    except ModelFilesError:
        venv.close()
        raise
    old_size = int(source.observation_space.shape[0])
    before = [index for index, count in blocks for _ in range(count)]  # np.insert's positions
    added = len(before)
    # Where each old observation value sits in the new one.
    moved_to = [old + sum(count for index, count in blocks if index <= old) for old in range(old_size)]
    venv = VecNormalize(venv, norm_obs=stats.norm_obs, norm_reward=stats.norm_reward, clip_obs=stats.clip_obs,
                        clip_reward=stats.clip_reward, gamma=stats.gamma, epsilon=stats.epsilon)
    venv.obs_rms.mean = np.insert(stats.obs_rms.mean, before, 0.0)
    venv.obs_rms.var = np.insert(stats.obs_rms.var, before, 1.0)
    venv.obs_rms.count = stats.obs_rms.count
    venv.ret_rms = stats.ret_rms
    model = algo_cls(source.policy_class, venv, policy_kwargs=source.policy_kwargs, seed=seed, device="cpu",
                     verbose=0, **model_kwargs)
    widened = model.policy.state_dict()  # views of the new model's parameters: filled in place
    with torch.no_grad():
        for name, weight in source.policy.state_dict().items():
            target = widened[name]
            if weight.shape == target.shape:
                target.copy_(weight)
            elif weight.dim() == 2 and target.shape == (weight.shape[0], weight.shape[1] + added):
                # A layer reading the observation (a critic reads it followed by the action):
                # the new values get zero weights, the old ones keep theirs where they moved.
                target.zero_()
                target[:, moved_to] = weight[:, :old_size]
                target[:, old_size + added:] = weight[:, old_size:]
            else:
                raise ConfigError(f"--init-from {model_dir}: cannot widen {name} from {tuple(weight.shape)} "
                                  f"to {tuple(target.shape)}")
    model.num_timesteps = source.num_timesteps
    return model, venv


def load_trained(model_dir: Path, algo_cls, venv, **load_kwargs: Any):
    """The SB3 model in ``model_dir`` and its VecNormalize statistics around ``venv``.

    :raises ModelFilesError: a damaged ``model.zip`` or ``vecnormalize.pkl``.
    """
    from stable_baselines3.common.vec_env import VecNormalize

    check_sb3_zip(model_dir / MODEL_FILE)
    try:
        venv = VecNormalize.load(str(model_dir / STATS_FILE), venv)
    except Exception as error:
        venv.close()
        raise damaged(model_dir / STATS_FILE, error, "VecNormalize statistics") from None
    return algo_cls.load(model_dir / MODEL_FILE, env=venv, device="cpu", **load_kwargs), venv


def with_driver_profile(hyper: Hyperparameters, profile_path: str, source: str) -> Hyperparameters:
    """``hyper`` with a driver profile's timing and response in its environment's randomisation
    (saved so in the run's config.json: a resumed run keeps them).

    :raises ConfigError: the profile is invalid, or the file's randomisation is off (the
        profile's driver is drawn in the perturbed episodes; there would be none).
    """
    from ..sim.driver_profile import load_driver_profile

    profile = load_driver_profile(profile_path)
    env = copy.deepcopy(dict(hyper.env))
    randomisation = dict(env.get("randomisation") or {})
    if not randomisation.get("enabled", False):
        raise ConfigError(f"--driver-profile {profile_path}: {source} has env.randomisation.enabled false; the "
                          "profile's driver is drawn in the perturbed episodes: use a file with randomisation "
                          "(e.g. ppo_reach or ppo_grasp_chain)")
    randomisation.update(profile.env_randomisation())
    env["randomisation"] = randomisation
    updated = dataclasses.replace(hyper, env=env)
    updated.check(f"{source} with --driver-profile {profile_path}")
    return updated


def train(run: TrainRun, t_start: Optional[float] = None,
          extra_callbacks: Optional[Callable[[Path, Dict[str, Any], Dict[str, Any]], Sequence[Any]]] = None) -> int:
    """Run (or resume) one training run; returns the exit status (0 done, 130 interrupted).

    :param run: the run's settings; to resume, ``run.resume`` set and the settings merged with
        the run's ``config.json`` by :meth:`TrainRun.resumed`.
    :param t_start: wall-clock start (s since the epoch), for wall time and time to solve;
        None: now.
    :param extra_callbacks: called as ``extra_callbacks(run_dir, meta, summary)``; the SB3
        callbacks it returns run after the evaluation callback at every step (e.g. reporting
        to Ray Tune, see :mod:`fr5_rl.training.tune.trial`).
    :raises ConfigError: a configuration problem, before any training time is spent.
    """
    t_start = time.time() if t_start is None else t_start
    if run.resume:
        saved = read_run_config(run.run_dir)
        source = str(Path(run.run_dir) / "config.json")
        differ = [name for name in FIXED_ON_RESUME if getattr(run, name) != saved.get(name)]
        if differ:
            raise ConfigError(f"{source}: the run's {differ[0]} is {saved.get(differ[0])!r}, these settings' "
                              f"{getattr(run, differ[0])!r}; merge them with TrainRun.resumed() to resume it")
        hyper = typed(Hyperparameters, saved["hyperparams_resolved"], f"{source}: hyperparams_resolved")
        trained_for = hyper.env.get("robot", DEFAULT_ROBOT)
        if run.robot is not None and run.robot != trained_for:
            raise ConfigError(f"{source}: the run trains for the {trained_for}, not the {run.robot}: resume it "
                              "without --robot, or start a new run")
    else:
        source = str(hyperparameter_source(run.algo, run.task, run.hyperparams))
        hyper = load_hyperparameters(run.algo, run.task, run.hyperparams)
        if run.driver_profile:
            hyper = with_driver_profile(hyper, run.driver_profile, source)
        if run.robot is not None:
            hyper = dataclasses.replace(hyper, env={**hyper.env, "robot": run.robot})
        run = dataclasses.replace(
            run, n_envs=run.n_envs or hyper.n_envs, timesteps=int(run.timesteps or hyper.n_timesteps),
            run_dir=run.run_dir if run.run_dir is not None
            else Path("runs") / f"{run.task}_{run.algo}_{time.strftime('%Y%m%d-%H%M%S')}")
    run.check()
    earlier = [name for name in (CONFIG_FILE, "final", "checkpoints", "monitor") if (Path(run.run_dir) / name).exists()]
    if not run.resume and earlier:
        if not run.force:
            raise ConfigError(f"{run.run_dir} holds a run already: continue it with --resume --run-dir {run.run_dir}, "
                              "pick a new --run-dir (or leave it out for a fresh one), or pass --force to replace it")
        for name in earlier:  # --force: nothing of the old run mixes into the new one
            path = Path(run.run_dir) / name
            shutil.rmtree(path) if path.is_dir() else path.unlink()
    for warning in check_hyperparameters(run.algo, hyper, run.n_envs, source):
        print(f"train.py: warning: {warning}", file=sys.stderr)
    if run.subprocess and run.start_method == "forkserver" and (run.processes or available_cores()) > 1:
        from .fork_server import start_fork_server

        start_fork_server()  # before torch: the workers' imports happen meanwhile, on another core
    import torch
    from stable_baselines3.common.vec_env import VecNormalize

    from .callbacks import REPLAY_FILE, save_checkpoint

    torch.set_num_threads(max(run.torch_threads, 1))
    # torch.distributions checks every distribution's parameters when it is built: a policy call
    # per step and every minibatch of the update build one. The checks compute nothing the
    # run uses (the same seed trains to the same weights without them) and cost ~5 % of a reach run.
    torch.distributions.Distribution.set_default_validate_args(False)
    run_dir = Path(run.run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "monitor").mkdir(exist_ok=True)

    from ..envs import FR5Env  # after argument checks: imports pybullet

    env_overrides = hyper.env
    probe = FR5Env(task=run.task, config=env_overrides)
    meta = build_meta(run.task, run.algo, env_overrides, probe.cfg,
                      probe.observation_space.shape[0], probe.action_space.shape[0], probe.control_dt,
                      run.seed, n_envs=run.n_envs, trained_by="rl")
    probe.close()

    venv = make_vec_env(run.task, env_overrides, run.n_envs, run.seed, run_dir / "monitor", run.subprocess,
                        run.start_method, run.processes, hyper.expert_start)
    # The evaluation's episodes run on every core too (its workers wait, idle, while training
    # steps), with one policy call per step for all of them: 40 episodes one after the other
    # in this process were a seventh of a reach run.
    eval_env = make_vec_env(run.task, env_overrides, min(run.eval_envs, run.eval_episodes),
                            run.seed + EVAL_SEED_OFFSET, None, run.subprocess, run.start_method, run.processes)
    algo_cls = algorithm_class(run.algo)
    latest = run_dir / "checkpoints" / "latest"
    summary_path = run_dir / "summary.json"
    summary: Dict[str, Any] = json.loads(summary_path.read_text()) if run.resume and summary_path.is_file() else {}
    elapsed_before = float(summary.get("wall_time_s", 0.0))

    try:
        if run.resume and recover_model_dir(latest):
            model, venv = load_trained(latest, algo_cls, venv)
            if (latest / REPLAY_FILE).is_file():
                model.load_replay_buffer(latest / REPLAY_FILE)
            print(f"train.py: resuming {run_dir} from step {model.num_timesteps}")
        elif run.init_from is not None and not run.resume:
            model, venv = initialise_from(run.init_from, run.task, run.algo, venv, meta, run_dir, hyper.algo_kwargs)
            meta["initialised_from"] = {"model": str(run.init_from), "num_timesteps": int(model.num_timesteps)}
            model.num_timesteps = 0  # --timesteps counts this run's steps
            write_run_config(run_dir, run, hyper, init_from=str(run.init_from))
            print(f"train.py: starting from {run.init_from} ({meta['initialised_from']['num_timesteps']} steps)")
        else:
            if run.resume:
                print(f"train.py: {run_dir} has no checkpoint yet; starting it from scratch")
            norm = hyper.normalize
            venv = VecNormalize(venv, norm_obs=norm.norm_obs, norm_reward=norm.norm_reward, clip_obs=norm.clip_obs,
                                gamma=float(hyper.algo_kwargs.get("gamma", 0.99)))
            kwargs = dict(hyper.algo_kwargs)
            policy = kwargs.pop("policy", "MlpPolicy")
            model = algo_cls(policy, venv, seed=run.seed, device="cpu", tensorboard_log=str(run_dir / "tb"),
                             verbose=0, **kwargs)
            write_run_config(run_dir, run, hyper)
    except BaseException:
        # A model refused here (another task, damaged files) leaves no worker processes behind.
        close_vec_env(venv, True)
        close_vec_env(eval_env, True)
        raise
    eval_env = VecNormalize(eval_env, training=False, norm_obs=venv.norm_obs, norm_reward=False,
                            clip_obs=venv.clip_obs)
    summary.update({"task": run.task, "algo": run.algo, "seed": run.seed, "n_envs": run.n_envs,
                    "machine": machine_description(), "target_success": run.target_success})
    callbacks, evaluation = build_callbacks(run, run_dir, eval_env, meta, t_start - elapsed_before, summary)
    if hyper.critic_warmup is not None:
        from .callbacks import CriticWarmup

        callbacks.callbacks.insert(0, CriticWarmup(hyper.critic_warmup.steps, hyper.critic_warmup.learning_rate))
    if hyper.expert_start is not None:
        from .curriculum import ExpertStartCurriculum

        callbacks.callbacks.insert(0, ExpertStartCurriculum(hyper.expert_start, run_dir))
    if extra_callbacks is not None:
        callbacks.callbacks.extend(extra_callbacks(run_dir, meta, summary))
    remaining = max(run.timesteps - int(model.num_timesteps), 0)
    interrupted = False
    try:
        model.learn(total_timesteps=remaining, callback=callbacks, reset_num_timesteps=False,
                    progress_bar=run.progress, tb_log_name="run")
    except KeyboardInterrupt:
        interrupted = True
        print("\ntrain.py: interrupted; saving a checkpoint before exiting", file=sys.stderr)
    save_checkpoint(model, run_dir, meta)
    if not interrupted:
        save_model_dir(run_dir / "final", model, venv, {**meta, "num_timesteps": int(model.num_timesteps)})
    summary["evaluations_skipped"] = int(summary.get("evaluations_skipped", 0)) + evaluation.skipped
    summary.update({"num_timesteps": int(model.num_timesteps),
                    "wall_time_s": round(elapsed_before + time.time() - t_start, 1),
                    "finished": not interrupted})
    write_json_atomic(summary_path, summary)
    close_vec_env(venv, interrupted)
    close_vec_env(eval_env, interrupted)
    print(f"train.py: {'stopped' if interrupted else 'done'} at {model.num_timesteps} steps; "
          f"run directory {run_dir}")
    if interrupted:
        print(f"train.py: continue it with: rosrun fr5_rl train.py --resume --run-dir {run_dir}")
    else:
        print(f"train.py: the model is {run_dir / 'final'} (the best evaluated: {run_dir / 'best'}); evaluate it with: "
              f"rosrun fr5_rl evaluate.py {run_dir / 'final'}")
    return 130 if interrupted else 0
