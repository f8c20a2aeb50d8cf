"""The reverse curriculum of expert-prefixed starts (training/curriculum.py); its wiring into train.py is in
test_training.py."""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from fr5_rl.envs import FR5Env
from fr5_rl.training.curriculum import STATE_FILE, ExpertStartCurriculum, ExpertStartWrapper
from fr5_rl.training.hyperparameters import ExpertStartSettings

pytestmark = pytest.mark.slow  # training with expert starts: `make test`, not `make test-fast`


@pytest.fixture(scope="module")
def grasp_env():
    env = ExpertStartWrapper(FR5Env("grasp"), max_steps=70)
    yield env
    env.close()


def test_no_reach_back_is_the_plain_reset(grasp_env):
    plain = FR5Env("grasp")
    try:
        grasp_env.set_reach_back(None)
        observation, info = grasp_env.reset(seed=5)
        expected, _ = plain.reset(seed=5)
        assert info["expert_steps"] == 0
        np.testing.assert_array_equal(observation, expected)
    finally:
        plain.close()


def test_starts_lie_along_the_experts_trajectory(grasp_env):
    grasp_env.set_reach_back(1.0)
    grasp_env.reset(seed=11)
    prefixes, lifted = [], 0
    for _ in range(24):
        observation, info = grasp_env.reset()
        env = grasp_env.unwrapped
        prefixes.append(info["expert_steps"])
        assert 0 <= info["expert_steps"] <= 70
        assert env.episode.steps == info["expert_steps"]  # the prefix counts toward the step limit
        state = env.task_state()
        lifted += state.object_position[2] - state.object_start_position[2] > 0.02
        # The observation returned is the state the policy starts from, and the episode goes on.
        np.testing.assert_allclose(observation, env.episode.observe()[1], atol=1e-6)
        _, _, terminated, truncated, _ = grasp_env.step(np.zeros(7, dtype=np.float32))
        assert not truncated
    assert len(set(prefixes)) > 10  # drawn, not fixed
    assert lifted >= 3  # the late starts hold the cup up already: the lift reward is near


def test_a_short_reach_back_starts_near_the_end(grasp_env):
    grasp_env.set_reach_back(0.2)
    assert grasp_env.prefix_range() == (56, 70)
    grasp_env.reset(seed=12)
    for _ in range(6):
        _, info = grasp_env.reset()
        assert 56 <= info["expert_steps"] <= 70, info
        state = grasp_env.unwrapped.task_state()
        assert state.fingers_object_contact == 2  # the expert holds the cup by then


def test_frontier_draws_start_furthest_back_and_are_reported():
    env = ExpertStartWrapper(FR5Env("grasp"), max_steps=70, frontier_share=0.5)
    try:
        env.set_reach_back(0.5, frontier_end=42)  # the level before drew from 42 on
        assert env.prefix_range() == (35, 70)
        env.reset(seed=21)
        prefixes = []
        for _ in range(24):
            _, info = env.reset()
            assert 35 <= info["expert_steps"] <= 70
            prefixes.append(info["expert_steps"])
            # Only the episode's last step reports how it began (the env step stays as it was).
            _, _, _, _, step_info = env.step(np.zeros(7, dtype=np.float32))
            assert "expert_steps" not in step_info
        # Half the draws from a fifth of the range: far more than a uniform draw's fifth lands there.
        assert 0.35 <= np.mean(np.array(prefixes) < 42) <= 0.9
        assert max(prefixes) >= 42  # the rest of the range is still drawn
        env.set_reach_back(None)
        _, info = env.reset()
        assert info["expert_steps"] == 0
        done = False
        while not done:
            _, _, terminated, truncated, step_info = env.step(np.zeros(7, dtype=np.float32))
            done = terminated or truncated
        assert step_info["expert_steps"] == 0
    finally:
        env.close()


def test_a_prefix_that_would_end_the_episode_is_drawn_shorter():
    env = ExpertStartWrapper(FR5Env("grasp"), max_steps=250)  # longer than the expert's ~80-step solve
    try:
        env.reset(seed=3)
        for _ in range(12):
            _, info = env.reset()
            assert info["expert_steps"] < 100
            assert env.unwrapped.task.lifted_time < env.unwrapped.task.hold_time
    finally:
        env.close()


def test_the_curriculum_moves_starts_back_and_resumes(tmp_path):
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv

    venv = DummyVecEnv([lambda: ExpertStartWrapper(FR5Env("grasp"), 70) for _ in range(2)])
    try:
        from stable_baselines3.common.logger import configure

        model = PPO("MlpPolicy", venv, n_steps=64, batch_size=64, device="cpu")
        model.set_logger(configure(None, []))
        settings = ExpertStartSettings(max_steps=70, first_reach_back=0.25, promote_at=0.75, window=4, step_back=0.25,
                                       frontier_share=0.5)
        callback = ExpertStartCurriculum(settings, tmp_path)
        callback.init_callback(model)
        callback.on_training_start({}, {})
        assert venv.get_attr("reach_back") == [0.25, 0.25]

        def episodes(*successes, expert_steps=None):
            for success in successes:
                # A start at the current level's first prefix (its frontier) unless told otherwise.
                level = callback.reach_back or 1.0  # the plain task: prefix 0
                steps = round((1 - level) * 70) if expert_steps is None else expert_steps
                callback.update_locals({"infos": [{"is_success": success, "expert_steps": steps}, {}],
                                        "dones": np.array([True, False])})
                callback.on_step()

        episodes(True, False, False, False)  # 1 in 4: stays
        assert callback.reach_back == 0.25
        episodes(True, True, False, True)  # the window holds the last 4: 3 of them succeeded at the last
        assert callback.reach_back == 0.5 and venv.get_attr("reach_back") == [0.5, 0.5]
        assert json.loads((tmp_path / STATE_FILE).read_text())["reach_back"] == 0.5
        assert callback.frontier_end == 52 and venv.get_attr("frontier_end") == [52, 52]
        # Episodes begun at the first level (prefixes 52-70) end after the step back: later,
        # easier starts than the new frontier (35-51), they do not count.
        episodes(True, True, True, True, expert_steps=52)
        assert callback.reach_back == 0.5
        episodes(True, True, True)  # a fresh window: 3 episodes are not enough
        assert callback.reach_back == 0.5
        for _ in range(2):
            episodes(True, True, True, True)
        assert callback.reach_back == 1.0  # starts anywhere from the reset on
        episodes(True, True, True, True)
        assert callback.reach_back is None and venv.get_attr("reach_back") == [None, None]  # the plain task
        episodes(True, True, True, True)
        assert callback.reach_back is None
        saved = json.loads((tmp_path / STATE_FILE).read_text())
        assert saved["reach_back"] is None
        assert [h["reach_back"] for h in saved["history"]] == [0.25, 0.5, 0.75, 1.0, None]

        resumed = ExpertStartCurriculum(settings, tmp_path)
        venv.env_method("set_reach_back", 1.0)
        resumed.init_callback(model)
        resumed.on_training_start({}, {})
        assert resumed.reach_back is None and venv.get_attr("reach_back") == [None, None]
        # Resumed mid-way, the frontier is again what the last step back added.
        (tmp_path / STATE_FILE).write_text(json.dumps({"reach_back": 0.75, "history": saved["history"][:3]}))
        resumed = ExpertStartCurriculum(settings, tmp_path)
        resumed.init_callback(model)
        resumed.on_training_start({}, {})
        assert venv.get_attr("reach_back") == [0.75, 0.75] and venv.get_attr("frontier_end") == [35, 35]
    finally:
        venv.close()


# ----------------------------------------------------------------------------- one replay, several starts
def test_a_saved_episode_goes_on_exactly_as_it_did():
    """FR5Env.save_state / restore_state: in a plain configuration a restored episode takes the
    same steps to the bit (observations, rewards, verdicts), restored twice over."""
    from fr5_rl.expert import ScriptedExpert

    env = FR5Env("grasp")
    expert = ScriptedExpert(env)
    try:
        observation, _ = env.reset(seed=7)
        for _ in range(45):  # the fingers about to close round the cup
            observation, *_ = env.step(expert.act(observation))
        saved = env.save_state()

        def go_on():
            taken, current = [], observation
            for _ in range(40):
                current, reward, terminated, truncated, info = env.step(expert.act(current))
                taken.append((current.tobytes(), reward, terminated, truncated, info["is_success"], env.episode.steps))
                if terminated or truncated:
                    break
            return taken

        first = go_on()
        assert first[-1][4]  # the expert lifted and held the cup
        env.restore_state(saved)
        assert go_on() == first
        env.restore_state(saved)
        assert go_on() == first
        env.discard_state(saved)
    finally:
        env.close()


def test_one_replay_serves_several_starts():
    """episodes_per_replay=2: two starts drawn at once; the second reset plays the one saved on
    the way, at its own prefix, with the observation it had there, without replaying anything."""
    env = ExpertStartWrapper(FR5Env("grasp"), max_steps=70, reach_back=1.0, episodes_per_replay=2)
    steps = {"count": 0}
    inner = env.unwrapped
    original_step = inner.step

    def counted(action):
        steps["count"] += 1
        return original_step(action)

    inner.step = counted
    try:
        env.reset(seed=31)
        env.reset()  # the start saved by the seeded reset's replay
        for _ in range(6):
            steps["count"] = 0
            first, info_first = env.reset()
            replayed = steps["count"]
            assert replayed == info_first["expert_steps"]  # one replay to the furthest start
            placement = inner.episode.object_start
            env.step(np.zeros(7, dtype=np.float32))  # the first episode moves on
            steps["count"] = 0
            second, info_second = env.reset()
            assert steps["count"] == 0  # nothing replayed: the saved start is played
            assert info_second["expert_steps"] <= info_first["expert_steps"]
            assert inner.episode.steps == info_second["expert_steps"]
            assert inner.episode.object_start == placement  # the same replay's placement
            np.testing.assert_allclose(second, inner.episode.observe()[1], atol=1e-6)
        # A new level discards what was drawn under the one before.
        env.reset()
        env.set_reach_back(None)
        _, info = env.reset()
        assert info["expert_steps"] == 0
    finally:
        del inner.step
        env.close()


def _spare_wrapper(frontier_share: float = 0.5) -> ExpertStartWrapper:
    return ExpertStartWrapper(FR5Env("grasp"), max_steps=70, reach_back=0.3, frontier_share=frontier_share,
                              spare=FR5Env("grasp"))


@pytest.fixture
def spare_wrapper():
    """Builds grasp wrappers with a spare (:func:`_spare_wrapper`) and closes them after the test."""
    built = []

    def build(frontier_share: float = 0.5) -> ExpertStartWrapper:
        built.append(_spare_wrapper(frontier_share))
        return built[-1]

    yield build
    for env in built:
        env.close()


def _rollout_with_idle_work(env: ExpertStartWrapper, idle_units, steps: int = 160):
    """Random actions with automatic resets; ``idle_units(step)`` units of idle work after each
    step; a level change part-way. Everything the policy would see, step by step."""
    actions = np.random.default_rng(4).uniform(-1, 1, (steps, 7)).astype(np.float32)
    trace = []
    observation, info = env.reset(seed=8)
    trace.append((observation, info["expert_steps"]))
    for step, action in enumerate(actions):
        if step == 90:
            env.set_reach_back(0.6, frontier_end=49)
        observation, reward, terminated, truncated, info = env.step(action)
        trace.append((observation, reward, terminated, truncated))
        if terminated or truncated:
            observation, info = env.reset()
            trace.append((observation, info["expert_steps"]))
        for _ in range(idle_units(step)):
            env.idle_work()
    return trace


def test_a_spare_prepares_the_same_starts_however_its_work_is_spread():
    """The spare's next start comes out the same whether it was prepared in idle time, all of
    it, none of it (at the reset) or some of it: every observation, reward and start identical."""
    traces = []
    for idle_units in (lambda step: 0, lambda step: 1000, lambda step: step % 7):
        env = _spare_wrapper()
        try:
            traces.append(_rollout_with_idle_work(env, idle_units))
        finally:
            env.close()
    starts = [entry[1] for entry in traces[0] if len(entry) == 2]
    assert len(starts) >= 6 and len(set(starts)) > 2  # several episodes, drawn starts
    for other in traces[1:]:
        assert len(other) == len(traces[0])
        for expected, got in zip(traces[0], other):
            for a, b in zip(expected, got):
                np.testing.assert_array_equal(a, b)


def test_a_prepared_start_is_played_without_a_replay_and_the_two_environments_swap(spare_wrapper):
    env = spare_wrapper(frontier_share=0.0)
    spare_steps = {"count": 0}
    env.reset(seed=3)
    live, spare = env.unwrapped, env._spare.unwrapped
    original_step = spare.step

    def counted(action):
        spare_steps["count"] += 1
        return original_step(action)

    spare.step = counted
    while env.idle_work():  # the process's idle time: the next start replayed in the spare
        pass
    prepared_steps = spare_steps["count"]
    assert prepared_steps >= 49  # reach_back 0.3 of 70: a start at step 49 or later
    observation, info = env.reset()
    assert spare_steps["count"] == prepared_steps  # nothing replayed at the reset itself
    assert env.unwrapped is spare and env._spare.unwrapped is live
    assert info["expert_steps"] == prepared_steps == spare.episode.steps
    np.testing.assert_allclose(observation, spare.episode.observe()[1], atol=1e-6)
    state = spare.task_state()
    assert state.fingers_object_contact == 2  # late along the expert's grasp: it holds the cup
    _, _, terminated, truncated, _ = env.step(np.zeros(7, dtype=np.float32))
    assert spare.episode.steps == prepared_steps + 1  # the policy's steps go to the swapped-in one
    del spare.step


def test_an_error_preparing_a_start_is_raised_by_the_reset_that_needs_it(spare_wrapper):
    env = spare_wrapper()
    env.reset(seed=5)
    spare = env._spare.unwrapped

    def broken(action):
        raise RuntimeError("physics server lost")

    spare.step = broken
    assert env.idle_work()  # the error is kept, not raised in idle time
    assert not env.idle_work()
    with pytest.raises(RuntimeError, match="physics server lost"):
        env.reset()


def test_an_attribute_of_the_environment_set_through_the_wrapper_reaches_the_spare_too(spare_wrapper):
    env = spare_wrapper()
    env.reset(seed=6)
    env.unwrapped.marker, env._spare.unwrapped.marker = "x", "y"
    assert env.set_wrapper_attr("marker", "z")
    assert env.unwrapped.marker == "z" and env._spare.unwrapped.marker == "z"
    env.set_wrapper_attr("probe", 1)  # nobody has it: it lands on the wrapper, as Gymnasium's does
    assert env.probe == 1 and not hasattr(env.unwrapped, "probe")


def test_a_spare_needs_one_start_per_replay():
    with pytest.raises(ValueError, match="episodes_per_replay"):
        ExpertStartWrapper(FR5Env("grasp"), max_steps=70, episodes_per_replay=2, spare=FR5Env("grasp"))
    from fr5_rl.config import ConfigError

    settings = ExpertStartSettings(max_steps=70, first_reach_back=0.2, promote_at=0.6, window=100, step_back=0.1,
                                   frontier_share=0.5, episodes_per_replay=2, prepare_ahead=True)
    with pytest.raises(ConfigError, match="prepare_ahead"):
        settings.check("ppo_grasp.yaml")
    with pytest.raises(ConfigError, match="true or false"):  # YAML's "yes" in quotes, say
        dataclasses.replace(settings, episodes_per_replay=1, prepare_ahead="yes").check("ppo_grasp.yaml")
