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


def _toy_fit(schedule: str, gripper_loss_weight: float = 1.0, epochs: int = 8):
    """A small actor fitted to a map it cannot hold exactly; returns (loss, learner, data)."""
    rng = np.random.default_rng(1)
    observations = rng.uniform(-1, 1, (3000, 24)).astype(np.float32)
    # A learnable map under label noise (as the expert's labels are, seen through a noisy
    # observation): a constant rate keeps jumping about its best fit.
    labels = (np.tanh(3.0 * observations[:, :7]) + rng.normal(0.0, 0.3, (3000, 7))).astype(np.float32)
    normaliser = imitation.Normaliser(observations)
    algo_kwargs = {"n_steps": 64, "batch_size": 64, "policy_kwargs": {"net_arch": {"pi": [64, 64], "vf": [16]}}}
    model, _ = imitation.build_model_and_stats("grasp", {}, algo_kwargs, normaliser, seed=0)
    loss = imitation.fit(model, normaliser, observations, labels, epochs=epochs, learning_rate=3e-3,
                         schedule=schedule, gripper_loss_weight=gripper_loss_weight, seed=3)
    return loss, imitation.make_learner(model, normaliser), observations, labels


def test_cosine_schedule_anneals_the_rate_to_zero():
    assert imitation.learning_rate_at("cosine", 1e-3, 0.0) == pytest.approx(1e-3)
    assert imitation.learning_rate_at("cosine", 1e-3, 0.5) == pytest.approx(5e-4)
    assert imitation.learning_rate_at("cosine", 1e-3, 1.0) == pytest.approx(0.0, abs=1e-12)
    assert imitation.learning_rate_at("constant", 1e-3, 0.9) == 1e-3


def test_gripper_weight_buys_the_gripper_component_accuracy():
    def gripper_error(weight):
        _, learner, observations, labels = _toy_fit("cosine", weight)
        actions = np.array([learner(o) for o in observations[:500]])
        return np.mean((actions[:, 6] - labels[:500, 6]) ** 2)

    assert gripper_error(8.0) < gripper_error(1.0)


def test_workers_roll_out_and_evaluate_the_episodes_the_serial_loop_does():
    from fr5_rl.envs import FR5Env
    from fr5_rl.expert import ScriptedExpert

    env = FR5Env(task="grasp")
    observations, labels, success = imitation.rollouts(env, ScriptedExpert(env), None, 3, 500, 1.0,
                                                       np.random.default_rng(0))
    algo_kwargs = {"n_steps": 64, "batch_size": 64, "policy_kwargs": {"net_arch": {"pi": [32], "vf": [16]}}}
    normaliser = imitation.Normaliser(observations)
    model, _ = imitation.build_model_and_stats("grasp", {}, algo_kwargs, normaliser, seed=0)
    imitation.fit(model, normaliser, observations, labels, epochs=2)
    serial_rate = imitation.evaluate(env, imitation.make_learner(model, normaliser), 3, 900)
    workers = imitation.RolloutWorkers(2, "grasp", {"training": {}, "task": {}})
    try:
        # The expert alone: no draw decides who acts, so the data are the serial loop's exactly.
        parallel = workers.rollouts(None, 3, 500, 1.0, np.random.default_rng(0))
        parallel_rate = workers.evaluate("task", imitation.ActorSnapshot(model, normaliser), 3, 900)
    finally:
        workers.close()
    np.testing.assert_array_equal(parallel[0], observations)
    np.testing.assert_array_equal(parallel[1], labels)
    assert parallel[2] == pytest.approx(success)
    assert parallel_rate == pytest.approx(serial_rate)


def test_workers_below_one_are_refused(capsys):
    assert imitate.main(["--workers", "0"]) == 2
    assert "--workers must be at least 1" in capsys.readouterr().err


def test_a_run_with_workers_gives_a_loadable_model(tmp_path):
    run = tmp_path / "run"
    assert imitate.main(["--task", "grasp", "--rounds", "1", "--episodes", "2", "--epochs", "1",
                         "--eval-episodes", "2", "--workers", "2", "--run-dir", str(run)]) == 0
    summary = json.loads((run / "summary.json").read_text())
    assert [h["round"] for h in summary["history"]] == [0, 1]
    assert load_policy(run / "final", "torch").observation_size == 24


def _tiny(run, *extra):
    return imitate.main(["--task", "grasp", "--episodes", "2", "--epochs", "2", "--eval-episodes", "1",
                         "--seed", "5", "--run-dir", str(run), *extra])


def _actor_weights(run):
    return load_policy(run / "final", "torch").model.policy.state_dict()


def test_a_run_stopped_after_a_round_resumes_into_the_unbroken_run(tmp_path):
    """A run that finished 1 round and is resumed to 3 labels, fits and ends as one run of 3
    (the data set, the generator and the actor all come back)."""
    import torch

    assert _tiny(tmp_path / "whole", "--rounds", "3") == 0
    assert _tiny(tmp_path / "broken", "--rounds", "1") == 0
    assert _tiny(tmp_path / "broken", "--rounds", "3", "--resume") == 0
    whole = json.loads((tmp_path / "whole" / "summary.json").read_text())["history"]
    resumed = json.loads((tmp_path / "broken" / "summary.json").read_text())["history"]
    assert [h["round"] for h in resumed] == [0, 1, 2, 3]
    assert [h["samples"] for h in resumed] == [h["samples"] for h in whole]
    assert [h["fit_loss"] for h in resumed[1:]] == pytest.approx([h["fit_loss"] for h in whole[1:]])
    for name, value in _actor_weights(tmp_path / "whole").items():
        assert torch.equal(value, _actor_weights(tmp_path / "broken")[name]), name


def test_a_run_killed_between_rounds_resumes_from_the_last_round_it_finished(tmp_path):
    """The state written after round 1's data joined the set, with round 2 never begun (as a
    kill during round 2's fit leaves it): the resume continues at round 2."""
    run = tmp_path / "run"
    assert _tiny(run, "--rounds", "2") == 0
    state_path = run / imitation.STATE_DIR / imitation.STATE_FILE
    state = json.loads(state_path.read_text())
    assert state["finished"] == 2 and state["next_round"] == 2
    # Round 2's fit never happened: drop it from the record, as a kill during it leaves it.
    state["finished"] = None
    state["history"] = state["history"][:2]
    state_path.write_text(json.dumps(state))
    assert _tiny(run, "--rounds", "2", "--resume") == 0
    history = json.loads((run / "summary.json").read_text())["history"]
    assert [h["round"] for h in history] == [0, 1, 2]


def test_resume_refuses_another_run_and_a_run_with_nothing_done(tmp_path, capsys):
    run = tmp_path / "run"
    assert _tiny(run, "--rounds", "1", "--resume") == 2
    assert "no finished DAgger round to resume" in capsys.readouterr().err
    assert _tiny(run, "--rounds", "1") == 0
    assert imitate.main(["--task", "grasp", "--episodes", "3", "--epochs", "2", "--eval-episodes", "1",
                         "--seed", "5", "--run-dir", str(run), "--rounds", "2", "--resume"]) == 2
    assert "episodes 2 (given 3)" in capsys.readouterr().err
    assert imitate.main(["--resume"]) == 2
    assert "--resume needs --run-dir" in capsys.readouterr().err
