"""Fine-tuning: --init-from (a trained model as the start, its observation widened by blocks it
lacks, the critic warmed up) and training from the scripted expert's states (expert_start)."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

from fr5_rl.cli import train
from fr5_rl.config import ConfigError
from fr5_rl.training.algorithms import load_hyperparameters
from fr5_rl.training.curriculum import STATE_FILE

from training_helpers import (DEFAULT_REACH_SIZE, FAST_PPO, FAST_PPO_WITH_HINT, read_json, write)

pytestmark = pytest.mark.slow  # short training runs: `make test`, not `make test-fast`


# ----------------------------------------------------------------------------- --init-from (fine-tuning)
def test_init_from_continues_the_given_model(ppo_run, tmp_path):
    """A fine-tuning run starts from the given weights and statistics (not from scratch) and
    counts its own steps; its meta says where it came from."""
    import torch
    from stable_baselines3 import PPO

    source = ppo_run / "checkpoints" / "latest"
    run_dir = tmp_path / "fine"
    code = train.main(["--init-from", str(source), "--timesteps", "512", "--n-envs", "32", "--no-subprocess",
                       "--checkpoint-freq", "256", "--eval-freq", "100000", "--no-progress", "--run-dir", str(run_dir)])
    assert code == 0
    meta = read_json(run_dir / "final" / "meta.json")
    assert meta["initialised_from"]["model"] == str(source) and meta["initialised_from"]["num_timesteps"] >= 6000
    assert 512 <= meta["num_timesteps"] < 6000  # this run's steps only
    before = PPO.load(source / "model.zip", device="cpu").policy.state_dict()
    after = PPO.load(run_dir / "final" / "model.zip", device="cpu").policy.state_dict()
    moved = [float((after[k] - before[k]).abs().max()) for k in before if before[k].dtype == torch.float32]
    assert max(moved) > 0.0  # it trained ...
    assert max(moved) < 0.5  # ... a little, from the source's weights (a fresh init is far away)


def test_init_from_applies_this_runs_settings_and_warms_the_critic_up(ppo_run, tmp_path):
    """--init-from with a hyperparameter file: the file's training settings (learning rate,
    n_steps, clip range) replace the saved model's; with critic_warmup, the actor's weights stay
    exactly as they were while only the value function learns, then the actor trains too."""
    import torch
    from stable_baselines3 import PPO

    source = ppo_run / "checkpoints" / "latest"
    hyper = write(tmp_path / "fine.yaml", FAST_PPO_WITH_HINT.replace("n_steps: 256", "n_steps: 128")
                  .replace("learning_rate: 0.0003", "learning_rate: 0.00002")
                  + "  clip_range: 0.05\n" + "critic_warmup: {steps: 256, learning_rate: 0.001}\n")

    def fine_tune(timesteps: int) -> dict:
        run_dir = tmp_path / f"fine_{timesteps}"
        code = train.main(["--init-from", str(source), "--hyperparams", str(hyper), "--timesteps", str(timesteps),
                           "--n-envs", "1", "--no-subprocess", "--eval-freq", "100000", "--no-progress",
                           "--run-dir", str(run_dir)])
        assert code == 0
        return PPO.load(run_dir / "final" / "model.zip", device="cpu")

    before = PPO.load(source / "model.zip", device="cpu").policy.state_dict()
    held = fine_tune(256)  # two rollouts of 128: both inside the warm-up
    assert (held.learning_rate, held.n_steps, held.clip_range(1.0)) == (0.00002, 128, 0.05)
    state = held.policy.state_dict()
    actor = [k for k in before if k.startswith(("mlp_extractor.policy_net", "action_net", "log_std"))]
    critic = [k for k in before if k.startswith(("mlp_extractor.value_net", "value_net"))]
    assert actor and critic
    for key in actor:
        assert torch.equal(state[key], before[key]), f"{key} moved during the critic warm-up"
    assert max(float((state[k] - before[k]).abs().max()) for k in critic) > 0.0
    released = fine_tune(768).policy.state_dict()  # the last rollouts train the actor as well
    assert max(float((released[k] - before[k]).abs().max()) for k in actor) > 0.0


def test_init_from_with_more_previous_actions_starts_from_the_same_policy(ppo_run, tmp_path):
    """A model trained without previous actions in its observation can start a run that has them:
    the widened network acts exactly as the source on every observation, whatever the new values
    hold (their weights start at zero), and the run trains from there. The new block goes where
    the layout puts it, before the joint-step hint, which keeps its weights."""
    import gymnasium as gym
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv

    import fr5_rl  # noqa: F401
    from fr5_rl.deploy.policy import load_policy
    from fr5_rl.training.train import load_widened

    source = ppo_run / "checkpoints" / "latest"
    hint = yaml.safe_load(FAST_PPO_WITH_HINT)["env"]["observation"]["joint_step_hint"]
    observation_cfg = {"previous_actions": 2, "joint_step_hint": hint}
    venv = DummyVecEnv([lambda: gym.make("FR5Reach-v0", config={"observation": observation_cfg})])
    model, widened = load_widened(source, PPO, venv, [(23, 12)], seed=0)
    before = load_policy(source, "torch")
    rng = np.random.default_rng(0)
    for _ in range(20):
        observation = rng.uniform(-1, 1, DEFAULT_REACH_SIZE).astype(np.float32)
        previous = rng.uniform(-1, 1, 12).astype(np.float32)
        wide = np.concatenate([observation[:23], previous, observation[23:]])
        action, _ = model.predict(widened.normalize_obs(wide), deterministic=True)
        np.testing.assert_allclose(np.clip(action, -1, 1), before.act(observation), atol=1e-5)
    venv.close()

    hyper = write(tmp_path / "wide.yaml", FAST_PPO_WITH_HINT.replace("{observation: {", "{observation: {previous_actions: 2, "))
    run_dir = tmp_path / "wide"
    code = train.main(["--init-from", str(source), "--hyperparams", str(hyper), "--timesteps", "256", "--n-envs", "1",
                       "--no-subprocess", "--eval-freq", "100000", "--no-progress", "--run-dir", str(run_dir)])
    assert code == 0
    meta = read_json(run_dir / "final" / "meta.json")
    assert meta["observation_size"] == DEFAULT_REACH_SIZE + 12 and meta["initialised_from"]["model"] == str(source)
    assert load_policy(run_dir / "final", "torch").act(np.zeros(DEFAULT_REACH_SIZE + 12)).shape == (7,)


def test_critic_warmup_settings_are_checked(tmp_path):
    with pytest.raises(ConfigError, match="critic_warmup.steps"):
        load_hyperparameters("ppo", "reach", str(write(tmp_path / "a.yaml", FAST_PPO + "critic_warmup: {steps: 0, learning_rate: 0.001}\n")))
    with pytest.raises(ConfigError, match="critic_warmup"):
        load_hyperparameters("ppo", "reach", str(write(tmp_path / "b.yaml", FAST_PPO + "critic_warmup: {steps: 100}\n")))


def test_init_from_refuses_another_task(ppo_run, tmp_path, capsys):
    code = train.main(["--task", "grasp", "--init-from", str(ppo_run / "checkpoints" / "latest"), "--timesteps",
                       "256", "--n-envs", "2", "--no-subprocess", "--no-progress", "--run-dir", str(tmp_path / "r")])
    assert code == 2
    assert "task is 'reach'" in capsys.readouterr().err


def test_expert_start_settings_are_checked(tmp_path):
    for bad, key in (("{max_steps: 0, first_reach_back: 0.2, promote_at: 0.5, window: 10, step_back: 0.1, frontier_share: 0.5}", "max_steps"),
                     ("{max_steps: 70, first_reach_back: 0.0, promote_at: 0.5, window: 10, step_back: 0.1, frontier_share: 0.5}", "first_reach_back"),
                     ("{max_steps: 70, first_reach_back: 0.2, promote_at: 0.0, window: 10, step_back: 0.1, frontier_share: 0.5}", "promote_at"),
                     ("{max_steps: 70, first_reach_back: 0.2, promote_at: 0.5, window: 10, step_back: 1.5, frontier_share: 0.5}", "step_back"),
                     ("{max_steps: 70, first_reach_back: 0.2, promote_at: 0.5, window: 10, step_back: 0.1, frontier_share: 1.5}", "frontier_share"),
                     ("{max_steps: 70, first_reach_back: 0.2, promote_at: 0.5, window: 10}", "expert_start")):
        path = tmp_path / "bad.yaml"
        write(path, FAST_PPO + f"expert_start: {bad}\n")
        with pytest.raises(ConfigError, match=key):
            load_hyperparameters("ppo", "grasp", str(path))


def test_train_runs_with_expert_starts(tmp_path):
    hyperparams = write(tmp_path / "ppo_grasp.yaml", FAST_PPO + "expert_start: {max_steps: 70, first_reach_back: 0.3, "
                                                                  "promote_at: 0.99, window: 20, step_back: 0.1, "
                                                                  "frontier_share: 0.5}\n")
    run_dir = tmp_path / "run"
    code = train.main(["--task", "grasp", "--hyperparams", str(hyperparams), "--timesteps", "1024", "--no-subprocess",
                       "--no-progress", "--eval-freq", "512", "--eval-episodes", "1", "--run-dir", str(run_dir)])
    assert code == 0
    config = read_json(run_dir / "config.json")
    assert config["hyperparams_resolved"]["expert_start"]["max_steps"] == 70
    # The curriculum ran in the training loop (its reach-back is logged every rollout; promote_at
    # 0.99 keeps it at the first one within these 1,024 steps, whatever the arm makes of them).
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    (logs,) = (run_dir / "tb").iterdir()
    events = EventAccumulator(str(logs))
    events.Reload()
    assert [value.value for value in events.Scalars("curriculum/reach_back")][0] == pytest.approx(0.3)
    assert read_json(run_dir / STATE_FILE)["history"][0]["reach_back"] == pytest.approx(0.3)
    # Its learning curve draws evaluation, training episodes and the reach-back.
    from fr5_rl.training.evaluation import plot_learning_curve, training_success

    steps, rate = training_success(run_dir / "monitor")
    assert steps[-1] <= 1024 and len(steps) == len(rate) and ((rate >= 0) & (rate <= 1)).all()
    assert plot_learning_curve(run_dir, tmp_path / "curve.png").stat().st_size > 10_000


def test_a_model_without_the_hint_fine_tunes_with_the_default_config_and_its_hint(tmp_path):
    """``train.py --task reach --init-from MODEL`` where MODEL was trained without the joint-step
    hint that config/ppo_reach.yaml adds (the reach models before 2026-11): the run widens it by
    those 6 values (zero weights), so it starts acting exactly as the model does."""
    import gymnasium as gym
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv

    import fr5_rl  # noqa: F401
    from fr5_rl.deploy.policy import load_policy
    from fr5_rl.training.train import load_widened

    plain = write(tmp_path / "plain.yaml", FAST_PPO)
    assert train.main(["--task", "reach", "--hyperparams", str(plain), "--timesteps", "512", "--no-subprocess",
                       "--eval-freq", "100000", "--no-progress", "--run-dir", str(tmp_path / "plain")]) == 0
    shipped = tmp_path / "plain" / "final"
    assert read_json(shipped / "meta.json")["observation_size"] == 23
    hint = yaml.safe_load(FAST_PPO_WITH_HINT)["env"]["observation"]
    venv = DummyVecEnv([lambda: gym.make("FR5Reach-v0", config={"observation": hint})])
    model, widened = load_widened(shipped, PPO, venv, [(23, 6)], seed=0)
    before = load_policy(shipped, "torch")
    rng = np.random.default_rng(1)
    for _ in range(20):
        observation = rng.uniform(-1, 1, 23).astype(np.float32)
        wide = np.concatenate([observation, rng.uniform(-1, 1, 6).astype(np.float32)])
        action, _ = model.predict(widened.normalize_obs(wide), deterministic=True)
        np.testing.assert_allclose(np.clip(action, -1, 1), before.act(observation), atol=1e-5)
    venv.close()

    run_dir = tmp_path / "fine"
    code = train.main(["--task", "reach", "--init-from", str(shipped), "--timesteps", "512", "--n-envs", "32",
                       "--no-subprocess", "--eval-freq", "100000", "--no-progress", "--run-dir", str(run_dir)])
    assert code == 0
    assert read_json(run_dir / "final" / "meta.json")["observation_size"] == DEFAULT_REACH_SIZE


def test_added_observation_blocks_say_where_the_new_values_go():
    from fr5_rl.training.train import added_observation_blocks

    hint = {"cartesian_step": 0.015, "rotation_step": 0.05, "damping": 0.05, "joint_step_scale": 0.04}

    def meta(size, previous=0, with_hint=False):
        return {"observation_size": size, "env_config": {"observation": {
            "previous_actions": previous, "joint_step_hint": hint if with_hint else None}}}

    assert added_observation_blocks(meta(23), meta(29, with_hint=True)) == [(23, 6)]
    assert added_observation_blocks(meta(29, with_hint=True), meta(41, 2, True)) == [(23, 12)]
    assert added_observation_blocks(meta(35, 2), meta(47, 3, True)) == [(35, 6), (35, 6)]
    assert added_observation_blocks(meta(23), meta(23)) == []  # nothing new
    assert added_observation_blocks(meta(29, with_hint=True), meta(23)) == []  # a block taken away
    assert added_observation_blocks(meta(35, 2), meta(29, 1)) == []
    assert added_observation_blocks(meta(24), meta(29, with_hint=True)) == []  # another layout (grasp)
