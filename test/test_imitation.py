"""DAgger from the scripted expert (fr5_rl.training.imitation): a tiny run produces a model
directory that the standard loader, ONNX export and evaluation accept, and its actor really
was fitted to the expert's labels."""
import json

import numpy as np

from fr5_rl.deploy.policy import load_policy
from fr5_rl.cli import imitate
from fr5_rl.training import imitation, onnx_export
import pytest

pytestmark = pytest.mark.slow  # DAgger runs: `make test`, not `make test-fast`


def test_tiny_dagger_run_gives_a_loadable_model(tmp_path):
    run = tmp_path / "run"
    assert imitate.main(["--task", "grasp", "--rounds", "2", "--episodes", "3", "--epochs", "3",
                           "--eval-episodes", "2", "--run-dir", str(run)]) == 0
    summary = json.loads((run / "summary.json").read_text())
    rounds = [h["round"] for h in summary["history"]]
    assert rounds == [0, 1, 2]
    # Round 2 aggregates round 0's demonstrations with the learner-driven round's labels.
    assert summary["history"][2]["samples"] > summary["history"][1]["samples"] > 0
    policy = load_policy(run / "final", "torch")
    assert policy.task == "grasp" and policy.observation_size == 24
    action = policy.act(np.zeros(24, dtype=np.float32))
    assert action.shape == (7,) and np.all(np.abs(action) <= 1.0)
    onnx_export.export(run / "final")
    assert onnx_export.parity(run / "final", 200) <= 1e-5


def test_fit_reduces_the_imitation_loss(tmp_path):
    rng = np.random.default_rng(0)
    observations = rng.uniform(-1, 1, (2000, 24)).astype(np.float32)
    labels = np.tanh(observations[:, :7] * 2.0)  # a learnable map
    normaliser = imitation.Normaliser(observations)
    algo_kwargs = {"n_steps": 64, "batch_size": 64, "policy_kwargs": {"net_arch": {"pi": [64, 64], "vf": [64]}}}
    model, _ = imitation.build_model_and_stats("grasp", {}, algo_kwargs, normaliser, seed=0)
    first = imitation.fit(model, normaliser, observations, labels, epochs=1)
    last = imitation.fit(model, normaliser, observations, labels, epochs=15)
    assert last < 0.5 * first
    learner = imitation.make_learner(model, normaliser)
    error = np.mean([np.abs(learner(o) - y).mean() for o, y in zip(observations[:100], labels[:100])])
    assert error < 0.2
