"""Where on the table a policy fails: success rate and failure causes by object placement.

An evaluation's per-episode records carry the object's start position (``object_x``,
``object_y``, m in base_link). This module bins them over the placement region into a grid of
cells (success rate, episodes, failure causes per cell), writes that grid as JSON, and draws it:
cells shaded by success rate, each episode a marker (success, or the failure's own marker).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Dict, List, Mapping, Sequence, Tuple

from ..deploy.bundle import write_json_atomic
from ..env_config import EnvConfig

# One marker per failure cause, so a cluster of one cause shows as one shape.
FAILURE_MARKERS = {"collision": "x", "timeout": "s", "left_workspace": "^", "object_knocked_over": "v",
                   "object_out_of_reach": "D"}


def success_map(records: Sequence[Mapping[str, Any]], region_low: Sequence[float], region_high: Sequence[float],
                bins: Tuple[int, int] = (4, 6)) -> Dict[str, Any]:
    """Bin episodes by the object's start position.

    :param records: per-episode records with ``object_x``, ``object_y`` (m, base_link),
        ``success`` and ``failure``.
    :param region_low: the placement region's (x, y) minimum (m, base_link).
    :param region_high: its (x, y) maximum (m).
    :param bins: cells along x and along y.
    :return: ``{"region_low", "region_high", "bins", "cells": [...]}``; each cell has its bounds,
        ``episodes``, ``successes``, ``success_rate`` (None when empty) and ``failures``.
    """
    (x_low, y_low), (x_high, y_high) = region_low, region_high
    nx, ny = int(bins[0]), int(bins[1])
    if nx < 1 or ny < 1 or x_high <= x_low or y_high <= y_low:
        raise ValueError(f"need bins >= 1 and a region with low < high; got bins {bins}, "
                         f"region {region_low} .. {region_high}")
    missing = [record.get("seed") for record in records if "object_x" not in record or "object_y" not in record]
    if missing:
        raise ValueError(f"{len(missing)} records have no object position (seeds {missing[:5]}...): "
                         "evaluate again with this version of evaluate.py")
    cells: List[Dict[str, Any]] = []
    for i in range(nx):
        for j in range(ny):
            cells.append({"x": [x_low + (x_high - x_low) * i / nx, x_low + (x_high - x_low) * (i + 1) / nx],
                          "y": [y_low + (y_high - y_low) * j / ny, y_low + (y_high - y_low) * (j + 1) / ny],
                          "episodes": 0, "successes": 0, "failures": {}})
    for record in records:
        # Clamped: a placement on the region's upper edge belongs to the last cell.
        i = min(nx - 1, max(0, int((float(record["object_x"]) - x_low) / (x_high - x_low) * nx)))
        j = min(ny - 1, max(0, int((float(record["object_y"]) - y_low) / (y_high - y_low) * ny)))
        cell = cells[i * ny + j]
        cell["episodes"] += 1
        if record["success"]:
            cell["successes"] += 1
        else:
            cause = str(record.get("failure") or "unknown")
            cell["failures"][cause] = cell["failures"].get(cause, 0) + 1
    for cell in cells:
        cell["success_rate"] = cell["successes"] / cell["episodes"] if cell["episodes"] else None
    return {"region_low": [x_low, y_low], "region_high": [x_high, y_high], "bins": [nx, ny], "cells": cells}


def plot_success_map(grid: Mapping[str, Any], records: Sequence[Mapping[str, Any]], out: Path, title: str) -> Path:
    """Draw ``grid`` (from :func:`success_map`) with every episode on it; write a PNG.

    Axes are base_link y (across the table, left to right as seen from the robot) and x
    (toward the robot at the top), in metres.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import cm, colors

    figure, axis = plt.subplots(figsize=(6.4, 4.8), dpi=110)
    shade = matplotlib.colormaps["RdYlGn"]
    norm = colors.Normalize(0.0, 1.0)
    for cell in grid["cells"]:
        (x0, x1), (y0, y1) = cell["x"], cell["y"]
        rate = cell["success_rate"]
        axis.add_patch(plt.Rectangle((y0, x0), y1 - y0, x1 - x0, edgecolor="0.6", linewidth=0.6,
                                     facecolor="0.92" if rate is None else shade(norm(rate)), alpha=0.55))
        if cell["episodes"]:
            axis.text((y0 + y1) / 2, (x0 + x1) / 2, f"{cell['successes']}/{cell['episodes']}", ha="center",
                      va="center", fontsize=7, color="0.15")
    wins = [record for record in records if record["success"]]
    axis.scatter([r["object_y"] for r in wins], [r["object_x"] for r in wins], s=9, c="tab:green",
                 marker="o", linewidths=0, label=f"success ({len(wins)})")
    causes = sorted({str(r.get("failure") or "unknown") for r in records if not r["success"]})
    for cause in causes:
        failed = [r for r in records if not r["success"] and str(r.get("failure") or "unknown") == cause]
        axis.scatter([r["object_y"] for r in failed], [r["object_x"] for r in failed], s=36, c="tab:red",
                     marker=FAILURE_MARKERS.get(cause, "*"), label=f"{cause} ({len(failed)})")
    (x_low, y_low), (x_high, y_high) = grid["region_low"], grid["region_high"]
    axis.set_xlim(y_low - 0.02, y_high + 0.02)
    axis.set_ylim(x_low - 0.02, x_high + 0.02)
    axis.set_aspect("equal")
    axis.set_xlabel("object y in base_link (m)")
    axis.set_ylabel("object x in base_link (m); the robot is above")
    axis.set_title(title, fontsize=10)
    figure.colorbar(cm.ScalarMappable(norm=norm, cmap=shade), ax=axis, label="cell success rate", shrink=0.8)
    axis.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=3, fontsize=8, frameon=False)
    figure.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(out)
    plt.close(figure)
    return out


def write_success_map(records: Sequence[Mapping[str, Any]], env_cfg: EnvConfig, out_stem: Path,
                      title: str, bins: Tuple[int, int] = (4, 6)) -> Tuple[Path, Path]:
    """The success map of ``records`` over ``env_cfg``'s placement region, as
    ``<out_stem>.json`` (the grid) and ``<out_stem>.png`` (the picture)."""
    region = env_cfg.object
    grid = success_map(records, region.region_low, region.region_high, bins)
    json_path, png_path = out_stem.with_suffix(".json"), out_stem.with_suffix(".png")
    write_json_atomic(json_path, {"title": title, **grid})
    plot_success_map(grid, records, png_path, title)
    return json_path, png_path
