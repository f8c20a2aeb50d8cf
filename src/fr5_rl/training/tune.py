"""Hyperparameter and seed sweeps on Ray Tune: what ``rosrun fr5_rl tune.py`` runs.

Each trial is a :func:`fr5_rl.training.train.train` run (VecNormalize, checkpoints, the
evaluation callback) of a hyperparameter file with sampled values set. After every evaluation
the trial reports its success rate and step count to Tune and hands Tune a checkpoint (the run
directory's model, statistics, config and summary), so a trial whose worker or node dies is
retried from there, on any node. ASHA stops weak trials at its rungs.

The search space is a YAML file (``config/search_<algo>_<task>.yaml``, :class:`SearchFile`).
The experiment (:class:`TuneExperiment`) writes into its output directory:

- ``results.csv`` / ``results.json``: one row per trial, best first (:func:`sort_rows`);
- ``success_vs_steps.png``: evaluation success against steps, one line per trial;
- ``best_hyperparams.yaml``: the best trial's hyperparameters, for ``train.py --hyperparams``;
- ``best_model/``: the best trial's model directory (``model.zip``, ``vecnormalize.pkl``,
  ``meta.json``, ``model.onnx``), for ``evaluate.py``, ``export_onnx.py`` and the policy node;
- ``tune/``: Ray Tune's experiment (trial checkpoints), which ``--resume`` continues;
- ``tune_settings.json``: everything ``--resume`` needs to rebuild the experiment.

Ray is imported inside functions only: importing this module needs no Ray.
"""
from __future__ import annotations

import argparse
import copy
import csv
import dataclasses
import json
import math
import os
import shutil
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Any, Dict, List, Mapping, Optional, Sequence

import yaml
from stable_baselines3.common.callbacks import BaseCallback

from ..config import ConfigError, load_yaml, typed
from ..runtime.bundle import META_FILE, read_meta, write_json_atomic
from .callbacks import save_checkpoint

EXPERIMENT_NAME = "tune"  # Tune's experiment directory under the storage path
SETTINGS_FILE = "tune_settings.json"
METRIC, MODE = "success", "max"  # what ASHA and the searcher optimise: the latest evaluation success
TIME_ATTR = "timesteps"  # ASHA's clock: environment steps
SEED_KEY = "seed"  # the one space key that is not in the hyperparameter file
SAMPLERS = ("uniform", "loguniform", "quniform", "randint", "choice", "grid")
# What a trial's checkpoint holds: all that train.py --resume reads, and the best model so far.
CHECKPOINT_ITEMS = ("config.json", "summary.json", "hyperparams.yaml", "checkpoints/latest", "best",
                    "eval/evaluations.npz")
TABLE_COLUMNS = ("rank", "trial_id", "status", "success", "final_success", "steps", "timesteps_to_solve",
                 "time_to_solve_s", "wall_s", "node_id", "node_ids", "start_step", "seed")


def import_ray():
    """``ray`` and ``ray.tune``, or a :class:`ConfigError` that says how to install them."""
    try:
        import ray
        from ray import tune
    except ImportError as error:
        raise ConfigError(f"Ray Tune is not installed ({error}); run `make setup` (it installs the pinned "
                          "ray[tune] from requirements.txt) and source env.sh") from None
    return ray, tune


# Names that moved from ray.train to ray.tune in Ray 2.x (Python 3.8's Ray 2.10 has them in ray.train).
_TUNE_API = ("report", "get_checkpoint", "get_context", "Checkpoint", "RunConfig", "FailureConfig",
             "CheckpointConfig")


def tune_api() -> SimpleNamespace:
    """The Tune functions and config classes, from ``ray.tune`` or (older Ray) ``ray.train``."""
    _, tune = import_ray()
    try:
        from ray import train as legacy
    except ImportError:  # pragma: no cover - a Ray without ray.train
        legacy = None
    return SimpleNamespace(**{name: getattr(tune, name, None) or getattr(legacy, name) for name in _TUNE_API})


# ----------------------------------------------------------------------------- the search file
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


# ----------------------------------------------------------------------------- the settings
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
                   processes: Optional[int] = None) -> ExperimentSettings:
    """Read the search and hyperparameter files and resolve the per-trial budget.

    :param max_timesteps: caps each trial's ``timesteps`` (smoke runs); evaluations (= reports)
        then come at most every ``max_timesteps / 2`` steps so that a trial reports at least twice.
    :param n_envs: overrides the search file's ``trial.n_envs``.
    :param processes: overrides the search file's ``trial.processes`` (see :func:`trial_processes`).
    :param storage: Tune's storage (a path on a file system every node sees, or a URI such as
        ``s3://bucket/dir``); default ``out`` itself.
    :raises ConfigError: a bad file, or hyperparameters that fail train.py's checks.
    """
    from .algorithms import check_hyperparameters, load_hyperparameters

    if samples < 1:
        raise ConfigError("--samples must be at least 1")
    spec = load_search_file(algo, task, space_path)
    base = load_hyperparameters(algo, task, spec.base).to_dict()
    timesteps = min(spec.trial.timesteps, max_timesteps) if max_timesteps else spec.trial.timesteps
    eval_freq = min(spec.trial.eval_freq, max(timesteps // 2, 1))
    n_envs = n_envs or spec.trial.n_envs
    if processes is not None and processes < 1:
        raise ConfigError(f"--processes must be at least 1, got {processes}")
    processes = trial_processes(n_envs, processes if processes is not None else spec.trial.processes)
    # The fixed values must make a valid file on their own (sampled ones are checked per trial).
    probe = trial_hyperparameters(base, spec.fixed, {}, n_envs, timesteps)
    from ..config import Hyperparameters

    check_hyperparameters(algo, typed(Hyperparameters, probe, f"{spec.base} + fixed"), n_envs, spec.base)
    out = Path(out).resolve()
    return ExperimentSettings(task=task, algo=algo, samples=samples, search=search, scheduler=scheduler,
                              search_file=dataclasses.asdict(spec), base_hyperparameters=base,
                              timesteps=int(timesteps), eval_freq=int(eval_freq), n_envs=int(n_envs),
                              seed=int(seed), out=str(out), storage=storage or str(out), processes=processes)


# ----------------------------------------------------------------------------- inside a trial
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

    from .train import train

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
        args = argparse.Namespace(
            task=settings["task"], algo=settings["algo"], hyperparams=str(run_dir / "hyperparams.yaml"),
            n_envs=settings["n_envs"], seed=int(config.get(SEED_KEY, settings["seed"])),
            timesteps=settings["timesteps"], run_dir=run_dir, resume=checkpoint is not None, init_from=None,
            checkpoint_freq=settings["eval_freq"], eval_freq=settings["eval_freq"],
            eval_episodes=spec.trial.eval_episodes, target_success=spec.trial.target_success,
            stop_at_success=spec.trial.stop_at_success, no_subprocess=processes == 1, processes=processes,
            no_progress=True, torch_threads=1, start_method="spawn")

        def reporter(directory: Path, meta: Dict[str, Any], summary: Dict[str, Any]) -> List[BaseCallback]:
            return [TuneReporter(directory, meta, summary, start_step, node_id)]

        code = train(args, time.time(), dict(vars(args)), extra_callbacks=reporter)
        if code != 0:
            raise RuntimeError(f"training stopped with status {code}")
    finally:
        shutil.rmtree(run_dir, ignore_errors=True)


# ----------------------------------------------------------------------------- the results
def trial_id(result: Any) -> str:
    """A Tune result's trial id (from its metrics, else its directory name)."""
    return str((result.metrics or {}).get("trial_id") or Path(str(result.path)).name)


def trial_rows(results: Sequence[Any], timesteps: int) -> List[Dict[str, Any]]:
    """One row per Tune result (trial): its config, node(s), success, steps, time to solve, and
    its evaluation history (``history``: ``[[steps, success, unix time], ...]``, for the plot)."""
    rows = []
    for result in results:
        metrics = dict(result.metrics or {})
        frame = result.metrics_dataframe
        history: List[List[float]] = []
        nodes: List[str] = []
        if frame is not None and len(frame) and TIME_ATTR in frame:
            frame = frame.dropna(subset=[TIME_ATTR])
            stamps = frame["timestamp"] if "timestamp" in frame else [0] * len(frame)
            history = [[int(s), float(v), int(t)] for s, v, t in zip(frame[TIME_ATTR], frame[METRIC], stamps)]
            nodes = [str(n) for n in dict.fromkeys(frame.get("node_id", []))]
        steps = int(metrics.get(TIME_ATTR, 0) or 0)
        solved = int(metrics.get("timesteps_to_solve", -1) or -1) >= 0
        if result.error is not None:
            status = "error"
        elif solved:
            status = "solved"
        elif steps < timesteps:
            status = "stopped early"
        else:
            status = "finished"
        config = {key: value for key, value in (result.config or {}).items()}
        rows.append({
            "trial_id": trial_id(result), "status": status,
            "success": max((h[1] for h in history), default=float(metrics.get("best_success", 0.0) or 0.0)),
            "final_success": float(metrics.get(METRIC, 0.0) or 0.0), "steps": steps,
            "timesteps_to_solve": int(metrics["timesteps_to_solve"]) if solved else None,
            "time_to_solve_s": float(metrics["time_to_solve_s"]) if solved else None,
            "wall_s": float(metrics.get("wall_s", 0.0) or 0.0),
            "node_id": str(metrics.get("node_id", "")), "node_ids": nodes,
            "start_step": int(metrics.get("start_step", 0) or 0), "seed": config.get(SEED_KEY),
            "config": config, "history": history,
            "error": None if result.error is None else str(result.error).splitlines()[0][:300],
        })
    return sort_rows(rows)


def sort_rows(rows: Sequence[Dict[str, Any]]) -> List[Dict[str, Any]]:
    """Best first: highest evaluation success, then fewest steps to solve, then fewest steps;
    errored trials last. Adds ``rank`` (1 = best)."""

    def key(row: Dict[str, Any]):
        to_solve = row.get("timesteps_to_solve")
        return (row.get("status") == "error", -float(row.get("success") or 0.0),
                math.inf if to_solve is None else to_solve, int(row.get("steps") or 0), str(row.get("trial_id")))

    ordered = [dict(row) for row in sorted(rows, key=key)]
    for rank, row in enumerate(ordered, 1):
        row["rank"] = rank
    return ordered


def write_results_table(rows: Sequence[Dict[str, Any]], out: Path) -> None:
    """``out/results.json`` (rows as they are) and ``out/results.csv`` (one column per config key)."""
    out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out / "results.json", {"trials": list(rows)})
    config_keys = sorted({key for row in rows for key in row["config"] if key != SEED_KEY})
    with open(out / "results.csv", "w", newline="", encoding="utf-8") as stream:
        writer = csv.writer(stream)
        writer.writerow(list(TABLE_COLUMNS) + config_keys + ["error"])
        for row in rows:
            cells = [";".join(row[c]) if c == "node_ids" else row.get(c) for c in TABLE_COLUMNS]
            writer.writerow(["" if v is None else v for v in cells]
                            + [row["config"].get(k, "") for k in config_keys] + [row.get("error") or ""])


def plot_success_vs_steps(rows: Sequence[Dict[str, Any]], out: Path, title: str) -> Path:
    """PNG of evaluation success against steps, one line per trial (best trial drawn thickest)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter, MaxNLocator

    from .evaluation import format_count

    fig, ax = plt.subplots(1, 1, figsize=(7, 4))
    for row in rows:
        if row["history"]:
            steps, success = [h[0] for h in row["history"]], [h[1] for h in row["history"]]
            ax.plot(steps, [100.0 * s for s in success], marker="o", ms=3, lw=2.5 if row["rank"] == 1 else 1.0,
                    label=f"#{row['rank']} {row['trial_id']} ({row['status']})")
    ax.set(xlabel="environment steps", ylabel="evaluation success (%)", ylim=(-2, 102), title=title)
    ax.grid(alpha=0.3)
    ax.xaxis.set_major_locator(MaxNLocator(nbins=6, steps=[1, 2, 2.5, 5, 10], integer=True, min_n_ticks=3))
    ax.xaxis.set_major_formatter(FuncFormatter(format_count))
    if len(rows) <= 12:
        ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def write_best_hyperparams(row: Dict[str, Any], settings: ExperimentSettings, path: Path) -> Path:
    """The best trial's hyperparameter file, for ``train.py --hyperparams``; its full-length
    ``n_timesteps`` is the base file's, not the trial's budget."""
    spec = settings.spec
    hyper = trial_hyperparameters(settings.base_hyperparameters, spec.fixed, row["config"], settings.n_envs,
                                  settings.base_hyperparameters["n_timesteps"])
    seed = row.get("seed")
    header = (f"# Best of {settings.samples} Ray Tune trials ({settings.search} search, scheduler "
              f"{settings.scheduler}): trial {row['trial_id']}, evaluation success {row['success']:.0%} "
              f"after {row['steps']} steps.\n"
              f"# rosrun fr5_rl train.py --task {settings.task} --algo {settings.algo} --hyperparams {path.name}"
              f"{f' --seed {seed}' if seed is not None else ''}\n")
    path.write_text(header + yaml.safe_dump(hyper, sort_keys=False), encoding="utf-8")
    return path


def copy_best_model(checkpoint, target: Path, row: Dict[str, Any]) -> Optional[Path]:
    """The best trial's best model (``best/``, else its latest checkpoint) as a model directory at
    ``target``, with ``model.onnx`` exported; None when the trial left no checkpoint."""
    if checkpoint is None:
        return None
    with tempfile.TemporaryDirectory(prefix="fr5_rl_best_") as scratch:
        source = Path(checkpoint.to_directory(scratch))
        model = source / "best" if (source / "best" / META_FILE).is_file() else source / "checkpoints" / "latest"
        if not (model / META_FILE).is_file():
            return None
        shutil.rmtree(target, ignore_errors=True)
        shutil.copytree(model, target, ignore=shutil.ignore_patterns("replay_buffer.pkl"))
    meta = read_meta(target)
    meta["tune"] = {"trial_id": row["trial_id"], "config": row["config"], "success": row["success"],
                    "node_id": row["node_id"]}
    write_json_atomic(target / META_FILE, meta)
    from .onnx_export import export

    export(target)
    return target


# ----------------------------------------------------------------------------- the experiment
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
