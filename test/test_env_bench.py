"""tools/bench/env_and_inference.py's reference stands in for the environment it is compared
with: the URDF alone, driven by the env's recorded commands, must move as the env's arm does in
every episode where that touched nothing (a reference with another speed cap, damping or physics
step would not)."""
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tools" / "bench"))

import env_floor as bench  # noqa: E402
from fr5_rl.envs import FR5Env  # noqa: E402


@pytest.mark.parametrize("task", ["reach", "grasp"])
def test_the_urdf_alone_moves_as_the_env_s_arm_in_every_untouched_episode(task):
    env = FR5Env(task=task)
    try:
        actions = np.random.default_rng(3).uniform(-1.0, 1.0, (600, 7)).astype(np.float32)
        episodes = bench.record_episodes(env, actions, first_seed=7)
        assert any(not episode["touched"] for episode in episodes)  # something to compare
        assert bench.replay_urdf_only(env, episodes)["same_motion_share"] == 1.0
    finally:
        env.close()


def test_the_minimal_env_replays_the_same_motion_and_runs_once_per_env_step(monkeypatch):
    env = FR5Env(task="reach")
    try:
        actions = np.random.default_rng(5).uniform(-1.0, 1.0, (400, 7)).astype(np.float32)
        episodes = bench.record_episodes(env, actions, first_seed=11)
        stepped = []
        minimal_step = bench._minimal_env_step
        monkeypatch.setattr(bench, "_minimal_env_step", lambda action, *results: stepped.append(action)
                            or minimal_step(action, *results))
        replay = bench.replay_bare(env, episodes, minimal_env=True)
        assert len(stepped) == len(actions)
        assert all(np.array_equal(a, b) for a, b in zip(stepped, actions))  # each step's own action, in order
        assert replay["max_final_joint_deviation_rad"] < 1e-4
        assert replay["env_reset_seconds"] > 0.0
    finally:
        env.close()
