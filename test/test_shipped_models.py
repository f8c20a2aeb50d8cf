"""Quality gates on the committed models (not timings): they load, their ONNX graphs match
SB3, their eval.json says what was measured, and they still solve their tasks here."""
import json
from pathlib import Path

import pytest

from fr5_rl.deploy.policy import load_policy
from fr5_rl.training.evaluation import run_episodes
from fr5_rl.training.onnx_export import parity

pytestmark = pytest.mark.slow  # every shipped model over many episodes: `make test`, not `make test-fast`

MODELS = Path(__file__).resolve().parent.parent / "models"
# model directory -> (task, episodes, minimum success rate)
GATES = {"reach": ("reach", 50, 0.90), "grasp": ("grasp", 30, 0.85)}


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
    records = run_episodes(task, policy.deployment_overrides(), lambda env: (policy.act, None), seeds)
    rate = sum(r["success"] for r in records) / episodes
    assert rate >= minimum, f"{name}: {rate:.0%} over {episodes} episodes, gate {minimum:.0%}"


def test_shipped_models_are_for_the_current_fr5():
    """Every shipped model records the arm it was trained for, and it is the FR5 sold today."""
    import json

    for name in GATES:
        assert json.loads((MODELS / name / "meta.json").read_text())["robot"] == "fr5", name


def test_grasp_holds_one_step_of_latency_with_every_perturbation():
    """The card's robustness: one control step of action latency, 5 mm observation noise and
    object mass and friction +-20 % together (98.5 % over its 200, 98.7 % over 600 fresh)."""
    policy = load_policy(MODELS / "grasp", "onnx", expected_task="grasp")
    perturbed = dict(policy.deployment_overrides(), randomisation={
        "enabled": True, "action_latency_steps": [1, 1], "observation_noise_std": 0.005,
        "object_mass_scale": [0.8, 1.2], "friction_scale": [0.8, 1.2], "object_size_scale": [1, 1],
        "joint_damping": [0, 0], "physics_dt_choices": [], "command_delay_s": [0, 0], "observation_age_s": [0, 0]})
    seeds = list(range(2_100_000, 2_100_030))
    records = run_episodes("grasp", perturbed, lambda env: (policy.act, None), seeds)
    rate = sum(r["success"] for r in records) / len(seeds)
    assert rate >= 0.85, f"grasp behind one step of latency: {rate:.0%} over {len(seeds)} episodes, gate 85%"


@pytest.mark.parametrize("name", sorted(GATES))
def test_shipped_onnx_matches_sb3(name):
    assert parity(MODELS / name, 1000) <= 1e-5
