"""The success map: episodes binned by object placement (fr5_rl.training.success_map), and
evaluate.py writing it beside its summary."""
import json

import pytest

from fr5_rl.cli.evaluate import main as evaluate_main
from fr5_rl.training.success_map import plot_success_map, success_map

LOW, HIGH = (-0.7, -0.3), (-0.3, 0.3)


def record(x, y, success, failure=""):
    return {"seed": 0, "object_x": x, "object_y": y, "success": success, "failure": failure}


def test_episodes_land_in_their_cells_with_their_causes():
    records = [record(-0.69, -0.29, True), record(-0.68, -0.25, False, "collision"),
               record(-0.31, 0.29, False, "timeout"), record(-0.3, 0.3, True)]  # the last on the upper edge
    grid = success_map(records, LOW, HIGH, bins=(2, 3))
    cells = grid["cells"]
    assert len(cells) == 6 and sum(cell["episodes"] for cell in cells) == 4
    first, last = cells[0], cells[-1]
    assert first["x"] == pytest.approx([-0.7, -0.5]) and first["y"] == pytest.approx([-0.3, -0.1])
    assert (first["episodes"], first["successes"], first["failures"]) == (2, 1, {"collision": 1})
    assert first["success_rate"] == pytest.approx(0.5)
    assert (last["episodes"], last["successes"], last["failures"]) == (2, 1, {"timeout": 1})
    assert [cell["success_rate"] for cell in cells[1:-1]] == [None] * 4  # empty cells say so


def test_records_without_positions_and_bad_grids_are_refused():
    with pytest.raises(ValueError, match="evaluate again"):
        success_map([{"seed": 7, "success": True, "failure": ""}], LOW, HIGH)
    with pytest.raises(ValueError, match="bins"):
        success_map([record(-0.5, 0.0, True)], LOW, HIGH, bins=(0, 2))
    with pytest.raises(ValueError, match="region"):
        success_map([record(-0.5, 0.0, True)], HIGH, LOW)


def test_plot_is_written(tmp_path):
    records = [record(-0.6, 0.1, True), record(-0.4, -0.2, False, "collision")]
    out = plot_success_map(success_map(records, LOW, HIGH), records, tmp_path / "map.png", "test")
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 5000


def test_evaluate_writes_the_map_of_its_episodes(tmp_path):
    out = tmp_path / "eval.json"
    assert evaluate_main(["--expert", "reach", "--episodes", "3", "--out", str(out)]) == 0
    grid = json.loads((tmp_path / "eval_map.json").read_text())
    per_episode = (tmp_path / "eval.csv").read_text().splitlines()
    assert sum(cell["episodes"] for cell in grid["cells"]) == 3 == len(per_episode) - 1
    assert sum(cell["successes"] for cell in grid["cells"]) == json.loads(out.read_text())["successes"]
    assert (tmp_path / "eval_map.png").stat().st_size > 5000
    header = per_episode[0].split(",")
    assert "object_x" in header and "object_y" in header
