"""FR5Env's rewards and step info (dense and sparse), and what the randomisation draws per episode
(plain episodes, timing shares, the failure penalty). Split from test_envs.py, whose helpers it uses."""
from __future__ import annotations

import numpy as np
import pytest

from fr5_rl.envs import FR5Env
from test_envs import TASKS, make, run_expert

# ----------------------------------------------------------------------------- rewards / info
REWARD_PARTS = ("reward_success", "reward_collision", "reward_failure", "reward_progress", "reward_action")


def check_info(reward, info):
    assert "is_success" in info and isinstance(info["is_success"], bool)
    assert "failure" in info
    parts = [k for k in info if k.startswith("reward_")]
    assert set(REWARD_PARTS) <= set(parts)
    assert sum(info[k] for k in parts) == pytest.approx(reward, abs=1e-9)


@pytest.mark.parametrize("task", TASKS)
def test_info_and_reward_parts(task):
    env = make(task)
    try:
        _, info = env.reset(seed=0)
        assert info["is_success"] is False
        rng = np.random.default_rng(3)
        progress = []
        for _ in range(400):
            _, reward, terminated, truncated, info = env.step(rng.uniform(-1, 1, 7).astype(np.float32))
            check_info(reward, info)
            progress.append(info["reward_progress"])
            assert info["is_success"] is False or terminated
            if truncated:
                assert info["failure"] == "timeout"
            if terminated or truncated:
                env.reset()
        assert np.std(progress) > 0  # the dense reward shapes
        run_expert(env, 0, on_step=check_info)
    finally:
        env.close()


@pytest.mark.parametrize("task", TASKS)
def test_sparse_reward_pays_only_success_and_failures(task):
    env = make(task, reward={"mode": "sparse", "failure_penalty": 3.0})
    try:
        bonus, penalty = env.cfg.reward.success_bonus, env.cfg.reward.collision_penalty
        other = {None: 0.0, "collision": 0.0, "timeout": 0.0}  # any other failure pays failure_penalty
        rng = np.random.default_rng(4)
        env.reset(seed=0)
        seen = set()

        def check(reward, info):
            expected = ((bonus if info["is_success"] else 0.0) - (penalty if info["failure"] == "collision" else 0.0)
                        - other.get(info["failure"], 3.0))
            assert info["reward_failure"] == -other.get(info["failure"], 3.0)
            assert reward == expected, (reward, info)
            assert info["reward_progress"] == 0.0 and info["reward_action"] == 0.0
            seen.add(expected)

        for _ in range(600):
            _, reward, terminated, truncated, info = env.step(rng.uniform(-1, 1, 7).astype(np.float32))
            check(reward, info)
            if terminated or truncated:
                env.reset()
        # Then down into the table (j2 and j3 forward, as a reach lowers the arm), until it ends.
        down = np.array([0.0, 1.0, 0.5, 0.0, 0.0, 0.0, 0.0], dtype=np.float32)
        for _ in range(env.cfg.task(task).max_steps):
            _, reward, terminated, truncated, info = env.step(down)
            check(reward, info)
            if terminated or truncated:
                break
        env.reset()
        if task == "reach":
            assert run_expert(env, 0, on_step=check)["is_success"]
            assert bonus in seen
        assert -penalty in seen and 0.0 in seen
    finally:
        env.close()


def test_success_step_pays_bonus_in_dense_mode():
    env = make("reach")
    try:
        rewards = []
        info = run_expert(env, 2, on_step=lambda r, i: rewards.append((r, i)))
        assert info["is_success"]
        reward, last = rewards[-1]
        assert last["reward_success"] == env.cfg.reward.success_bonus
        assert all(i["reward_success"] == 0.0 for _, i in rewards[:-1])
    finally:
        env.close()


def test_plain_episode_share_draws_some_episodes_without_randomisation():
    """randomisation.plain_episode_share: that share of episodes runs with none of the
    perturbations (here: two steps of latency and noise), the rest with all of them."""

    perturbed = {"enabled": True, "action_latency_steps": [2, 2], "observation_noise_std": 0.004}
    env = FR5Env(task="reach", config={"randomisation": {**perturbed, "plain_episode_share": 0.5}})
    latencies = []
    for seed in range(60):
        env.reset(seed=seed)
        latencies.append((env.episode.draws.action_latency_steps, env.episode.draws.observation_noise_std))
    env.close()
    assert set(latencies) == {(0, 0.0), (2, 0.004)}
    plain = sum(latency == (0, 0.0) for latency in latencies)
    assert 15 <= plain <= 45, plain  # binomial(60, 0.5): outside this 1 time in 10^4

    always = FR5Env(task="reach", config={"randomisation": perturbed})
    always.reset(seed=0)
    assert always.episode.draws.action_latency_steps == 2
    always.close()
    from fr5_rl.config import ConfigError

    with pytest.raises(ConfigError, match="plain_episode_share"):
        FR5Env(task="reach", config={"randomisation": {**perturbed, "plain_episode_share": 1.0}})


def test_target_action_latency_steps_replaces_the_latency_only_where_the_camera_is_drawn():
    """randomisation.target_action_latency_steps: the episodes that see the target through the
    camera's timing draw their whole-step latency from it (one more draw, so their placement
    differs); an episode (seeded per reset) without the camera is drawn exactly as without the key."""
    from fr5_rl.config import ConfigError

    perturbed = {"enabled": True, "action_latency_steps": [2, 2], "target_share": 0.5}
    before = FR5Env(task="grasp", config={"randomisation": perturbed})
    tied = FR5Env(task="grasp", config={"randomisation": {**perturbed, "target_action_latency_steps": [0, 1]}})
    camera_latencies = []
    try:
        for seed in range(40):
            _, info_before = before.reset(seed=seed)
            _, info_tied = tied.reset(seed=seed)
            assert (before.episode.draws.target is None) == (tied.episode.draws.target is None)
            assert before.episode.draws.object_dims == tied.episode.draws.object_dims
            if before.episode.draws.target is None:
                np.testing.assert_array_equal(info_before["object_start"], info_tied["object_start"])
                assert before.episode.draws.action_latency_steps == tied.episode.draws.action_latency_steps == 2
            else:
                assert before.episode.draws.action_latency_steps == 2
                camera_latencies.append(tied.episode.draws.action_latency_steps)
                assert before.episode.draws.target.latency == tied.episode.draws.target.latency
    finally:
        before.close()
        tied.close()
    assert 8 <= len(camera_latencies) <= 32, camera_latencies  # binomial(40, 0.5): outside this 1 time in 10^4
    assert set(camera_latencies) == {0, 1}
    with pytest.raises(ConfigError, match="target_action_latency_steps"):
        FR5Env(task="grasp", config={"randomisation": {**perturbed, "target_action_latency_steps": [1, 0]}})


@pytest.mark.parametrize("arm_steps, gripper_steps", [(0, 2), (2, 0), (1, 1)])
def test_gripper_latency_steps_delays_the_gripper_apart_from_the_arm(arm_steps, gripper_steps):
    """randomisation.gripper_latency_steps: the gripper's command acts that many steps late, the
    arm's after action_latency_steps; until its first action arrives each holds."""
    from fr5_rl.config import ConfigError

    env = FR5Env(task="grasp", config={"randomisation": {
        "enabled": True, "plain_episode_share": 0.0, "action_latency_steps": [arm_steps, arm_steps],
        "gripper_latency_steps": [gripper_steps, gripper_steps]}})
    try:
        env.reset(seed=3)
        open_width = env.episode.gripper_command_width
        action = np.zeros(7, dtype=np.float32)
        action[0], action[6] = 1.0, -1.0  # j1 on, gripper closed
        start_j1 = float(env.joint_positions()[0])
        widths, j1_moved = [], []
        for _ in range(4):
            env.step(action)
            widths.append(env.episode.gripper_command_width)
            j1_moved.append(abs(float(env.joint_positions()[0]) - start_j1) > 1e-3)
    finally:
        env.close()
    assert widths[:gripper_steps] == [open_width] * gripper_steps  # held open until its first action
    assert widths[gripper_steps] == pytest.approx(0.0)
    assert j1_moved.index(True) == arm_steps
    with pytest.raises(ConfigError, match="gripper_latency_steps"):
        FR5Env(task="grasp", config={"randomisation": {"gripper_latency_steps": [2, 1]}})


@pytest.mark.parametrize("steps", [0, 1, 2])
def test_gripper_latency_equal_to_the_arms_rolls_out_as_without_the_key(steps):
    """gripper_latency_steps [L, L] with action_latency_steps [L, L]: the same episodes, bit for
    bit, as the gripper sharing the arm's latency (a one-value range draws nothing)."""
    perturbed = {"enabled": True, "plain_episode_share": 0.0, "action_latency_steps": [steps, steps]}
    shared = FR5Env(task="grasp", config={"randomisation": perturbed})
    apart = FR5Env(task="grasp", config={"randomisation": {**perturbed, "gripper_latency_steps": [steps, steps]}})
    actions = np.random.default_rng(4).uniform(-1, 1, (120, 7)).astype(np.float32)
    try:
        for env in (shared, apart):
            env.reset(seed=11)
        for action in actions:
            obs_shared, reward_shared, *_ = shared.step(action)
            obs_apart, reward_apart, *_ = apart.step(action)
            np.testing.assert_array_equal(obs_shared, obs_apart)
            assert reward_shared == reward_apart
        assert apart.episode.draws.gripper_latency_steps == steps and shared.episode.draws.gripper_latency_steps is None
    finally:
        shared.close()
        apart.close()


def test_timing_share_leaves_some_perturbed_episodes_with_whole_step_latency_only():
    """randomisation.timing_share: that share of the perturbed episodes gets the in-period timing
    (command delay, observation age); the others keep their latency but no timing, so that "no
    jitter" never means "no latency" to the policy."""
    from fr5_rl.config import ConfigError

    perturbed = {"enabled": True, "action_latency_steps": [2, 2], "command_delay_s": [0.0, 0.02],
                 "observation_age_s": [0.0, 0.01]}
    env = FR5Env(task="reach", config={"randomisation": {**perturbed, "timing_share": 0.5}})
    drawn = []
    for seed in range(60):
        env.reset(seed=seed)
        draws = env.episode.draws
        drawn.append((draws.action_latency_steps, draws.command_delay_s, draws.observation_age_s))
    env.close()
    assert set(drawn) == {(2, (0.0, 0.0), (0.0, 0.0)), (2, (0.0, 0.02), (0.0, 0.01))}
    untimed = sum(d[1] == (0.0, 0.0) for d in drawn)
    assert 15 <= untimed <= 45, untimed  # binomial(60, 0.5): outside this 1 time in 10^4
    with pytest.raises(ConfigError, match="timing_share"):
        FR5Env(task="reach", config={"randomisation": {**perturbed, "timing_share": 1.5}})


def test_failure_penalty_is_paid_for_the_tasks_other_failures():
    from fr5_rl.tasks.base import TaskOutcome

    env = make("grasp", reward={"failure_penalty": 4.0})
    try:
        env.reset(seed=0)
        terms = env.task.terms(env.task_state())
        for failure, expected in ((None, 0.0), ("collision", 0.0), ("object_knocked_over", -4.0),
                                  ("object_out_of_reach", -4.0), ("left_workspace", -4.0)):
            parts = env.task.reward(TaskOutcome(False, failure, terms), [0.0] * 7)
            assert parts["failure"] == expected, failure
    finally:
        env.close()
    plain = make("grasp")
    assert plain.task.failure_penalty == 0.0  # off unless configured
    plain.close()


def test_grasp_point_height_moves_where_the_shaping_leads_the_tcp():
    """grasp.grasp_point_height raises the point the approach term and the close cue measure to;
    at 0 the terms are the object centre's, as before the key existed."""
    from fr5_rl.env_config import load_env_config
    from fr5_rl.tasks import GraspTask
    from fr5_rl.tasks.base import TaskState

    def state(tcp_z):
        return TaskState(joint_positions=[0.0] * 6, joint_velocities=[0.0] * 6, tcp_position=(-0.5, 0.0, tcp_z),
                         tcp_approach_axis=(0.0, 0.0, -1.0), gripper_width=0.08, tcp_to_object_distance=abs(tcp_z - 0.03),
                         object_position=(-0.5, 0.0, 0.03), object_up_axis=(0.0, 0.0, 1.0),
                         object_start_position=(-0.5, 0.0, 0.03), robot_table_contact=False, arm_object_contact=False,
                         fingers_object_contact=0, tcp_in_workspace=True)

    centre = GraspTask(load_env_config(), 0.08)
    raised = GraspTask(load_env_config({"grasp": {"grasp_point_height": 0.015}}), 0.08)
    at_centre, above = state(0.03), state(0.045)
    assert centre.terms(at_centre)["approach"] == 0.0
    assert raised.terms(above)["approach"] == pytest.approx(0.0, abs=1e-12)
    assert raised.terms(at_centre)["approach"] == pytest.approx(-0.015 / centre.distance_scale)
    # The cue to close: near the grasp point, not near the centre.
    assert centre.terms(at_centre)["gripper"] == pytest.approx(-1.0)  # wants 0 width, has 0.08 open
    assert raised.terms(above)["gripper"] == pytest.approx(-1.0)
    assert raised.terms(state(0.0))["gripper"] == pytest.approx(0.0)  # 4.5 cm from the point: stay open
