"""The driver: :class:`TuneExperiment` joins (or starts) Ray, builds the Tuner from the
experiment's settings, runs or resumes the sweep and writes the outputs (:mod:`.results`)."""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Dict, List, Optional

from ...config import ConfigError, typed
from ...deploy.bundle import write_json_atomic
from ..ray_compat import import_ray, tune_api
from .results import (copy_best_model, plot_success_vs_steps, trial_id, trial_rows, write_best_hyperparams,
                      write_results_table)
from .search_space import to_tune_space
from .settings import METRIC, MODE, SETTINGS_FILE, TIME_ATTR, ExperimentSettings
from .trial import run_trial

EXPERIMENT_NAME = "tune"  # Tune's experiment directory under the storage path


class TuneExperiment:
    """A Ray Tune sweep of train.py runs, from its settings to its output files.

    :param settings: from :func:`build_settings`, or ``tune_settings.json`` when resuming.
    :param address: a Ray cluster to join (``auto``, ``HOST:PORT``); None: ``RAY_ADDRESS`` if set,
        else a Ray started here for this experiment.
    """

    def __init__(self, settings: ExperimentSettings, address: Optional[str] = None) -> None:
        self.settings, self.address = settings, address
        self.out = Path(settings.out)
        self._started_ray = False

    @classmethod
    def from_directory(cls, out: Path, address: Optional[str] = None) -> "TuneExperiment":
        """The experiment whose outputs are in ``out`` (``tune.py --resume``)."""
        path = Path(out) / SETTINGS_FILE
        if not path.is_file():
            raise ConfigError(f"{path} is missing: --resume needs the --out directory of an earlier tune.py run")
        return cls(typed(ExperimentSettings, json.loads(path.read_text(encoding="utf-8")), str(path)), address)

    @property
    def experiment_path(self) -> str:
        return f"{self.settings.storage.rstrip('/')}/{EXPERIMENT_NAME}"

    def connect(self) -> None:
        """Join the cluster (or start a local Ray), then check that a trial fits on some node."""
        ray, _ = import_ray()
        if not ray.is_initialized():
            local = self.address is None and not os.environ.get("RAY_ADDRESS")
            ray.init(address=self.address, **({"include_dashboard": False} if local else {}),
                     logging_level="warning", log_to_driver=True)
            self._started_ray = True
        need = self.settings.trial_cpus
        largest = max((node["Resources"].get("CPU", 0.0) for node in ray.nodes() if node["Alive"]), default=0.0)
        if largest < need:
            raise ConfigError(f"a trial needs {need} CPUs (its {need} processes of {self.settings.n_envs} "
                              f"environments) on one node, but the largest node has {largest:g}; use "
                              f"--processes {max(int(largest), 1)} or larger nodes")

    def disconnect(self) -> None:
        if self._started_ray:
            import ray

            ray.shutdown()
            self._started_ray = False

    def trainable(self):
        _, tune = import_ray()
        settings = self.settings.to_dict()
        return tune.with_resources(tune.with_parameters(run_trial, settings=settings),
                                   {"cpu": self.settings.trial_cpus})

    def tuner(self):
        """A new Tuner for these settings."""
        _, tune = import_ray()
        api = tune_api()
        settings, spec = self.settings, self.settings.spec
        space = to_tune_space(spec.space, settings.search)
        if settings.search == "optuna":
            from ray.tune.search.optuna import OptunaSearch

            search_alg = OptunaSearch(metric=METRIC, mode=MODE, seed=settings.seed)
        else:
            from ray.tune.search.basic_variant import BasicVariantGenerator

            search_alg = BasicVariantGenerator(random_state=settings.seed)
        scheduler = None
        if settings.scheduler == "asha":
            from ray.tune.schedulers import ASHAScheduler

            scheduler = ASHAScheduler(time_attr=TIME_ATTR, max_t=settings.timesteps,
                                      grace_period=min(spec.asha.grace_period, settings.timesteps),
                                      reduction_factor=spec.asha.reduction_factor)
        run_config = api.RunConfig(
            name=EXPERIMENT_NAME, storage_path=settings.storage, verbose=1,
            failure_config=api.FailureConfig(max_failures=spec.trial.max_failures),
            checkpoint_config=api.CheckpointConfig(num_to_keep=2))
        return tune.Tuner(self.trainable(), param_space=space, run_config=run_config,
                          tune_config=tune.TuneConfig(metric=METRIC, mode=MODE, search_alg=search_alg,
                                                      scheduler=scheduler, num_samples=settings.samples))

    def run(self, resume: bool = False) -> List[Dict[str, Any]]:
        """Run (or, with ``resume``, continue) the sweep, then write the outputs; returns the rows.

        :raises ConfigError: no Ray, no node big enough for a trial, nothing to resume.
        """
        _, tune = import_ray()
        self.out.mkdir(parents=True, exist_ok=True)
        self.connect()
        try:
            if resume:
                if not tune.Tuner.can_restore(self.experiment_path):
                    raise ConfigError(f"{self.experiment_path} holds no Tune experiment to resume; start a new "
                                      "one without --resume")
                tuner = tune.Tuner.restore(self.experiment_path, trainable=self.trainable(), resume_errored=True)
            else:
                write_json_atomic(self.out / SETTINGS_FILE, self.settings.to_dict())
                tuner = self.tuner()
            grid = tuner.fit()
            return self.write_outputs(grid)
        finally:
            self.disconnect()

    def write_outputs(self, grid) -> List[Dict[str, Any]]:
        """results.csv/.json, success_vs_steps.png, best_hyperparams.yaml and best_model/."""
        results = [grid[index] for index in range(len(grid))]
        rows = trial_rows(results, self.settings.timesteps)
        write_results_table(rows, self.out)
        title = f"{self.settings.task} / {self.settings.algo}: {len(rows)} trials, scheduler {self.settings.scheduler}"
        plot_success_vs_steps(rows, self.out / "success_vs_steps.png", title)
        if rows and rows[0]["status"] != "error":
            best = rows[0]
            write_best_hyperparams(best, self.settings, self.out / "best_hyperparams.yaml")
            result = next(r for r in results if trial_id(r) == best["trial_id"])
            copy_best_model(result.checkpoint, self.out / "best_model", best)
        return rows
