"""An experiment's results, from Tune's trial results to the output files: one row per trial,
best first (:func:`trial_rows`, :func:`sort_rows`), ``results.csv``/``results.json``,
``success_vs_steps.png``, ``best_hyperparams.yaml`` and ``best_model/``."""
from __future__ import annotations

import csv
import math
import shutil
import tempfile
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence

import yaml

from ...deploy.bundle import META_FILE, read_meta, write_json_atomic
from .search_space import SEED_KEY, trial_hyperparameters
from .settings import METRIC, TIME_ATTR, ExperimentSettings

TABLE_COLUMNS = ("rank", "trial_id", "status", "success", "final_success", "steps", "timesteps_to_solve",
                 "time_to_solve_s", "wall_s", "node_id", "node_ids", "start_step", "seed")


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

    from ..evaluation import format_count

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
    from ..onnx_export import export

    export(target)
    return target
