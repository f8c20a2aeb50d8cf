"""What the benchmarks in tools/ share: paths, percentiles, verdicts, result files, summary.json.

    from benchlib import RESULTS_DIR, latency_ms, verdict, write_result, update_summary

    python tools/bench/benchlib.py summary [DIR]   # rebuild DIR/summary.json (default bench/results/)
                                             # from the "verdicts" of every result file in DIR

A bench measures, calls :func:`verdict` for each target (``"met"`` / ``"not met"``, with the
comparison written out), and writes its result with :func:`write_result`: the JSON gets the
machine description, a timestamp and the verdicts, and carries paths relative to the
repository only. :func:`update_summary` then replaces that bench's entries in ``summary.json``
and keeps every other bench's, so each bench can be re-run on its own.
``docs/bench/`` holds the published copy of the result files and their summary.

A bench that runs a launch file does it with ``roslaunch_run.run_launch`` (beside this file).

Imports only the standard library, numpy and ``fr5_rl.deploy.bundle``: no bench, no CLI.
"""
from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path
from typing import Any, Dict, Iterable, Mapping, Optional, Sequence

import numpy as np

REPO = Path(__file__).resolve().parents[2]
if str(REPO / "src") not in sys.path:
    sys.path.insert(0, str(REPO / "src"))

from fr5_rl.deploy.bundle import machine_description, write_json_atomic  # noqa: E402

RESULTS_DIR = REPO / "bench" / "results"  # where benches write by default
DOCS_BENCH_DIR = REPO / "docs" / "bench"  # the published copy the README cites
SUMMARY_FILE = "summary.json"

AT_MOST, AT_LEAST = "at most", "at least"
_SYMBOL = {AT_MOST: "<=", AT_LEAST: ">="}


# ----------------------------------------------------------------------------- paths
def relative_path(path: Any) -> str:
    """``path`` relative to the repository when inside it; outside it, only its last part (as
    ``.../name``), so no result carries a path of this machine. Relative paths are kept."""
    path = Path(path)
    if not path.is_absolute():
        return str(path)
    try:
        return str(path.resolve().relative_to(REPO)) or "."
    except ValueError:
        return f".../{path.name}"


def _scrub(value: Any) -> Any:
    """``value`` with every Path made relative and the repository's absolute path removed from
    every string (``/abs/repo/models/reach`` -> ``models/reach``)."""
    if isinstance(value, Path):
        return relative_path(value)
    if isinstance(value, str):
        root = str(REPO)
        return "." if value == root else value.replace(root + os.sep, "")
    if isinstance(value, Mapping):
        return {str(k): _scrub(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_scrub(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


# ----------------------------------------------------------------------------- statistics
def percentiles(values: Iterable[float], points: Sequence[float] = (50, 99)) -> Dict[str, Optional[float]]:
    """``{"p50": ..., "p99": ...}`` of the finite values (numpy's linear interpolation);
    None for each point when there are none."""
    data = np.asarray(list(values), dtype=float)
    data = data[np.isfinite(data)]
    return {f"p{point:g}": (float(np.percentile(data, point)) if data.size else None) for point in points}


def latency_ms(seconds: Iterable[float], points: Sequence[float] = (50, 99), digits: Optional[int] = None,
               mean: bool = False) -> Dict[str, Any]:
    """Durations given in seconds as ``p50_ms``, ``p99_ms`` (one key per point), ``max_ms``,
    ``samples`` and, with ``mean``, ``mean_ms``; rounded to ``digits`` when given."""
    data = np.asarray(list(seconds), dtype=float) * 1000.0
    data = data[np.isfinite(data)]

    def shown(value: Optional[float]) -> Optional[float]:
        return None if value is None else (round(value, digits) if digits is not None else value)

    result: Dict[str, Any] = {f"{key}_ms": shown(value) for key, value in percentiles(data, points).items()}
    if mean:
        result["mean_ms"] = shown(float(data.mean())) if data.size else None
    result["max_ms"] = shown(float(data.max())) if data.size else None
    result["samples"] = int(data.size)
    return result


# ----------------------------------------------------------------------------- verdicts
def verdict(measured: Optional[float], target: float, comparison: str, unit: str = "",
            what: str = "") -> Dict[str, Any]:
    """Measured against a target: ``comparison`` is ``"at most"`` or ``"at least"`` (the
    measured value must be at most / at least the target). None (nothing measured) is not met.

    Returns ``{"measured", "target", "comparison", "unit", "met": bool, "verdict": "met" |
    "not met", "text"}``, the text reading e.g. ``onnx p99 0.048 ms <= 0.2 ms: met``."""
    if comparison not in _SYMBOL:
        raise ValueError(f"comparison must be '{AT_MOST}' or '{AT_LEAST}', got {comparison!r}")
    if measured is None or not np.isfinite(measured):
        met, shown = False, "nothing measured"
    else:
        met = measured <= target if comparison == AT_MOST else measured >= target
        shown = f"{_number(measured)}{_unit(unit)} {_SYMBOL[comparison]} {_number(target)}{_unit(unit)}"
    word = "met" if met else "not met"
    return {"measured": None if measured is None else float(measured), "target": float(target),
            "comparison": comparison, "unit": unit, "met": bool(met), "verdict": word,
            "text": f"{what + ' ' if what else ''}{shown}: {word}"}


def _number(value: float) -> str:
    return f"{value:.3g}" if abs(value) < 1000 else f"{value:.0f}"


def _unit(unit: str) -> str:
    return "" if not unit else (unit if unit in ("x", "%") else f" {unit}")


def pass_fail(result: Mapping[str, Any]) -> str:
    """The ``PASS``/``FAIL`` word older result files carry for a :func:`verdict`."""
    return "PASS" if result["met"] else "FAIL"


# ----------------------------------------------------------------------------- machine
def machine_info() -> Dict[str, Any]:
    """:func:`fr5_rl.deploy.bundle.machine_description` plus the usable cores, the load when
    called and the versions of the libraries the figures depend on."""
    info: Dict[str, Any] = dict(machine_description())
    info["cores_usable"] = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    if hasattr(os, "getloadavg"):
        info["load_average_1min_at_start"] = round(os.getloadavg()[0], 2)
    from importlib.metadata import PackageNotFoundError, version

    for module in ("numpy", "pybullet", "torch", "onnxruntime", "stable_baselines3"):
        try:
            info[module] = version(module)
        except PackageNotFoundError:  # pragma: no cover - informational only
            pass
    return info


def timestamp() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%S%z")


# ----------------------------------------------------------------------------- output
def write_result(path: Path, data: Mapping[str, Any], verdicts: Optional[Mapping[str, Mapping[str, Any]]] = None,
                 machine: Optional[Mapping[str, Any]] = None) -> Path:
    """Write one bench's result as JSON (atomically), adding ``machine`` (the machine
    description, extended by ``machine`` when given), ``generated`` (now) and ``verdicts``.
    Paths become relative to the repository; no absolute path of it is written."""
    result = dict(data)
    result["machine"] = {**machine_description(), **dict(result.get("machine") or {}), **dict(machine or {})}
    result["generated"] = timestamp()
    if verdicts is not None:
        result["verdicts"] = dict(verdicts)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(path, _scrub(result))
    return path


def _bench_entry(file_name: str, result: Mapping[str, Any]) -> Dict[str, Any]:
    machine = result.get("machine") or {}
    entry = {"file": file_name, "quick": bool(result.get("quick", False)),
             "machine": {key: machine[key] for key in ("cpu", "cores", "python") if key in machine},
             "verdicts": dict(result.get("verdicts") or {})}
    if result.get("generated"):
        entry["generated"] = result["generated"]
    if result.get("skipped"):
        entry["skipped"] = result.get("reason", True)
    return entry


def _write_summary(results_dir: Path, benches: Mapping[str, Any]) -> Path:
    benches = dict(sorted(benches.items()))
    overview = {f"{bench}.{name}": v["text"] for bench, entry in benches.items()
                for name, v in sorted(entry["verdicts"].items())}
    flags = [v["met"] for entry in benches.values() for v in entry["verdicts"].values()]
    summary = {"generated": timestamp(), "targets_met": sum(flags), "targets_not_met": len(flags) - sum(flags),
               "verdicts": overview, "benches": benches}
    path = Path(results_dir) / SUMMARY_FILE
    path.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(path, _scrub(summary))
    return path


def read_summary_benches(results_dir: Path) -> Dict[str, Any]:
    """The per-bench entries of ``results_dir/summary.json`` (none when it is missing,
    unreadable or of the older format without ``benches``)."""
    path = Path(results_dir) / SUMMARY_FILE
    try:
        benches = json.loads(path.read_text(encoding="utf-8")).get("benches")
    except (OSError, ValueError, AttributeError):
        return {}
    return dict(benches) if isinstance(benches, dict) else {}


def update_summary(results_dir: Path, name: str, result_path: Path) -> Path:
    """Replace bench ``name``'s entry in ``results_dir/summary.json`` with the verdicts of the
    result file at ``result_path`` (written by :func:`write_result`), keeping every other
    bench's entry. Returns the summary's path."""
    result = json.loads(Path(result_path).read_text(encoding="utf-8"))
    benches = read_summary_benches(results_dir)
    benches[name] = _bench_entry(Path(result_path).name, result)
    return _write_summary(results_dir, benches)


def rebuild_summary(results_dir: Path) -> Path:
    """``results_dir/summary.json`` made afresh from every result file there that carries
    ``verdicts`` (how the published copy in docs/bench/ is made)."""
    benches = {}
    for path in sorted(Path(results_dir).glob("*.json")):
        if path.name == SUMMARY_FILE:
            continue
        try:
            result = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue
        if isinstance(result, dict) and result.get("verdicts"):
            benches[path.stem] = _bench_entry(path.name, result)
    return _write_summary(results_dir, benches)


def print_verdicts(verdicts: Mapping[str, Mapping[str, Any]]) -> None:
    for v in verdicts.values():
        print(f"  {v['text']}")


def main(argv: Optional[Sequence[str]] = None) -> int:
    import argparse

    parser = argparse.ArgumentParser(description="Rebuild summary.json from the result files of a directory.")
    parser.add_argument("command", choices=["summary"])
    parser.add_argument("directory", type=Path, nargs="?", default=RESULTS_DIR)
    args = parser.parse_args(argv)
    path = rebuild_summary(args.directory)
    summary = json.loads(path.read_text(encoding="utf-8"))
    for text in summary["verdicts"].values():
        print(text)
    print(f"wrote {relative_path(path)}: {summary['targets_met']} targets met, {summary['targets_not_met']} not met")
    return 0


if __name__ == "__main__":
    sys.exit(main())
