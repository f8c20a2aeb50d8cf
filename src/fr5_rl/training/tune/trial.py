"""The code a Ray worker runs for one trial: a :func:`fr5_rl.training.train.train` run
(:func:`run_trial`, Tune's trainable) that reports each evaluation to Tune with a checkpoint of
its run directory (:class:`TuneReporter`), and resumes from that checkpoint when Tune retries it."""
from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path
from typing import Any, Dict, List

import yaml
from stable_baselines3.common.callbacks import BaseCallback

from ...config import typed
from ...deploy.bundle import read_meta, write_json_atomic
from ..callbacks import save_checkpoint
from ..ray_compat import tune_api
from ..run_settings import TrainRun, read_run_config
from .search_space import SEED_KEY, SearchFile, trial_hyperparameters, trial_processes
from .settings import METRIC, SETTINGS_FILE, TIME_ATTR

# What a trial's checkpoint holds: all that train.py --resume reads, and the best model so far.
CHECKPOINT_ITEMS = ("config.json", "summary.json", "hyperparams.yaml", "checkpoints/latest", "best",
                    "eval/evaluations.npz")


class TuneReporter(BaseCallback):
    """After each evaluation of a training run: a checkpoint, then one ``tune.report`` with it.

    Runs after the evaluation callback (``train(..., extra_callbacks=...)``) and notices a new
    evaluation by a new entry in the run's ``summary['eval_history']``.

    :param run_dir: the trial's run directory.
    :param meta: the model's ``meta.json``.
    :param summary: the run's summary, updated by the evaluation callback.
    :param start_step: the step this attempt of the trial started from (0, or its checkpoint's).
    :param node_id: the Ray node this attempt runs on.
    """

    def __init__(self, run_dir: Path, meta: Dict[str, Any], summary: Dict[str, Any], start_step: int,
                 node_id: str) -> None:
        super().__init__()
        self.run_dir, self.meta, self.summary = run_dir, meta, summary
        self.start_step, self.node_id = int(start_step), node_id
        self._seen = len(summary.get("eval_history", []))

    def _on_step(self) -> bool:
        history = self.summary.get("eval_history", [])
        if len(history) > self._seen:
            self._seen = len(history)
            self.report(history)
        return True

    def report(self, history: List[Dict[str, Any]]) -> None:
        """Checkpoint the run directory and report the newest evaluation to Tune."""
        tune = tune_api()
        latest = history[-1]
        self.summary["wall_time_s"] = latest["wall_s"]  # a restarted attempt counts the time before it
        write_json_atomic(self.run_dir / "summary.json", self.summary)
        save_checkpoint(self.model, self.run_dir, self.meta)
        metrics = {METRIC: float(latest["success_rate"]), TIME_ATTR: int(latest["timesteps"]),
                   "best_success": max(float(h["success_rate"]) for h in history),
                   "wall_s": float(latest["wall_s"]), "node_id": self.node_id, "start_step": self.start_step,
                   "timesteps_to_solve": int(self.summary.get("timesteps_to_solve", -1)),
                   "time_to_solve_s": float(self.summary.get("time_to_solve_s", -1.0))}
        with tempfile.TemporaryDirectory(prefix="fr5_rl_checkpoint_") as staging:
            pack_checkpoint(self.run_dir, Path(staging))
            tune.report(metrics, checkpoint=tune.Checkpoint.from_directory(staging))


def pack_checkpoint(run_dir: Path, staging: Path) -> None:
    """Copy what resuming needs (:data:`CHECKPOINT_ITEMS`) from ``run_dir`` into ``staging``."""
    for item in CHECKPOINT_ITEMS:
        source, target = run_dir / item, staging / item
        if source.is_dir():
            shutil.copytree(source, target)
        elif source.is_file():
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, target)


def run_trial(config: Dict[str, Any], settings: Dict[str, Any]) -> None:
    """Tune's trainable: one train.py run of the sampled ``config``, resumed from Tune's
    checkpoint when this is a retry.

    :param config: the sampled values (dotted keys, and ``seed``).
    :param settings: :meth:`ExperimentSettings.to_dict`.
    :raises RuntimeError: training did not finish (Tune then retries it, up to ``max_failures``).
    """
    import ray

    from ..train import train

    tune = tune_api()
    spec = typed(SearchFile, settings["search_file"], SETTINGS_FILE)
    node_id = ray.get_runtime_context().get_node_id()
    processes = trial_processes(settings["n_envs"], settings.get("processes"))
    run_dir = Path(tempfile.mkdtemp(prefix=f"fr5_rl_trial_{tune.get_context().get_trial_id()}_"))
    try:
        checkpoint = tune.get_checkpoint()
        start_step = 0
        if checkpoint is not None:
            with checkpoint.as_directory() as source:
                shutil.copytree(source, run_dir, dirs_exist_ok=True)
            start_step = int(read_meta(run_dir / "checkpoints" / "latest").get("num_timesteps", 0))
        else:
            hyper = trial_hyperparameters(settings["base_hyperparameters"], spec.fixed, config,
                                          settings["n_envs"], settings["timesteps"])
            (run_dir / "hyperparams.yaml").write_text(yaml.safe_dump(hyper, sort_keys=False), encoding="utf-8")
        run = TrainRun(
            task=settings["task"], algo=settings["algo"], hyperparams=str(run_dir / "hyperparams.yaml"),
            n_envs=settings["n_envs"], seed=int(config.get(SEED_KEY, settings["seed"])),
            timesteps=settings["timesteps"], run_dir=run_dir, resume=checkpoint is not None, init_from=None,
            checkpoint_freq=settings["eval_freq"], eval_freq=settings["eval_freq"],
            eval_episodes=spec.trial.eval_episodes, target_success=spec.trial.target_success,
            stop_at_success=spec.trial.stop_at_success, subprocess=processes != 1, processes=processes,
            progress=False, torch_threads=1, start_method="spawn")
        if run.resume:  # a retry continues its checkpoint exactly as it was started: nothing is given again
            run = run.resumed(read_run_config(run_dir), typed_again=frozenset())

        def reporter(directory: Path, meta: Dict[str, Any], summary: Dict[str, Any]) -> List[BaseCallback]:
            return [TuneReporter(directory, meta, summary, start_step, node_id)]

        code = train(run, time.time(), extra_callbacks=reporter)
        if code != 0:
            raise RuntimeError(f"training stopped with status {code}")
    finally:
        shutil.rmtree(run_dir, ignore_errors=True)
