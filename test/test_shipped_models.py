"""Quality gates on the committed models (not timings): they load, their ONNX graphs match
SB3, their eval.json says what was measured, and they still solve their tasks here."""
import json
from pathlib import Path

import pytest

from fr5_rl.runtime.policy import load_policy
from fr5_rl.training.evaluation import run_episodes
from fr5_rl.training.onnx_export import parity

MODELS = Path(__file__).resolve().parent.parent / "models"
# model directory -> (task, episodes, minimum success rate); grasp_rl: PPO from reward alone.
GATES = {"reach": ("reach", 50, 0.90), "grasp": ("grasp", 30, 0.85), "grasp_rl": ("grasp", 30, 0.85)}


@pytest.mark.parametrize("name", sorted(GATES))
def test_shipped_model_directory_is_complete(name):
    directory, task = MODELS / name, GATES[name][0]
    for name in ("model.zip", "vecnormalize.pkl", "model.onnx", "meta.json", "eval.json"):
        assert (directory / name).is_file(), f"{directory / name} is missing"
        assert (directory / name).stat().st_size < 10 * 1024 * 1024
    report = json.loads((directory / "eval.json").read_text())
    for key in ("success_rate", "success_rate_95ci", "episodes", "seeds", "training_steps", "machine", "algo"):
        assert key in report, f"eval.json lacks {key}"
    assert report["episodes"] >= 200 and report["task"] == task
    assert report["success_rate_95ci"][0] <= report["success_rate"] <= report["success_rate_95ci"][1]


@pytest.mark.parametrize("name", sorted(GATES))
def test_shipped_model_still_solves_its_task(name):
    task, episodes, minimum = GATES[name]
    policy = load_policy(MODELS / name, "onnx", expected_task=task)
    seeds = list(range(2_000_000, 2_000_000 + episodes))  # not the seeds eval.json used
    records = run_episodes(task, {}, lambda env: (policy.act, None), seeds)
    rate = sum(r["success"] for r in records) / episodes
    assert rate >= minimum, f"{name}: {rate:.0%} over {episodes} episodes, gate {minimum:.0%}"


@pytest.mark.parametrize("name", sorted(GATES))
def test_shipped_onnx_matches_sb3(name):
    assert parity(MODELS / name, 1000) <= 1e-5
