"""evaluate.py --ray: episodes spread over a two-node Ray cluster on this machine (one CPU per
node) give the same per-episode outcomes and the same result files as a serial run."""
from __future__ import annotations

import csv
import json
import re
from pathlib import Path

import pytest

from fr5_rl.cli import evaluate
from fr5_rl.training.ray_eval import seed_slices

pytestmark = pytest.mark.slow  # a two-node Ray cluster: `make test`, not `make test-fast`

MODELS = Path(__file__).resolve().parent.parent / "models"
# Two slices of 4: the expert's episode of seed 3000004, the first of the second slice, ends
# 1e-5 m apart in a fresh environment and after seed 3000003 (see fr5_rl.training.ray_eval), so
# the comparison also checks that a slice replays the serial run's history.
SEED_START, EPISODES = 3_000_000, 8


def test_seed_slices_cover_every_seed_once_in_order():
    seeds = list(range(100, 111))
    for parts in (1, 2, 3, 4, 11, 20):
        slices = seed_slices(seeds, parts)
        assert [s for part in slices for s in part] == seeds
        assert len(slices) == min(parts, len(seeds)) and all(slices)
        assert max(map(len, slices)) - min(map(len, slices)) <= 1


def read_csv(path: Path) -> list:
    with open(path, newline="", encoding="utf-8") as stream:
        return list(csv.DictReader(stream))


@pytest.mark.parametrize("source", [["--expert", "reach"], [str(MODELS / "reach"), "--training-env"]],
                         ids=["expert", "model-randomised"])
def test_distributed_evaluation_equals_serial(cluster, tmp_path, capsys, source):
    # The randomised training env (noise, latency, physics step) makes outcomes differ per seed.
    common = [*source, "--episodes", str(EPISODES), "--seed-start", str(SEED_START)]
    assert evaluate.main([*common, "--out", str(tmp_path / "serial.json")]) == 0
    assert evaluate.main([*common, "--ray", "--out", str(tmp_path / "ray.json")]) == 0
    # SPREAD is best effort: on a loaded machine one node may finish both tasks before the
    # other's worker is up, so the count of nodes is not asserted (the sweep test asserts both
    # nodes); what must hold is the seeds cut into two tasks and the serial run's outcomes.
    assert re.search(r"evaluated on Ray: 2 tasks on [12] nodes", capsys.readouterr().out)
    serial, spread = read_csv(tmp_path / "serial.csv"), read_csv(tmp_path / "ray.csv")
    assert [r["seed"] for r in spread] == [str(s) for s in range(SEED_START, SEED_START + EPISODES)]
    assert spread == serial
    summaries = [json.loads((tmp_path / name).read_text()) for name in ("serial.json", "ray.json")]
    for summary in summaries:
        summary.pop("eval_wall_time_s")
    assert summaries[0] == summaries[1]
