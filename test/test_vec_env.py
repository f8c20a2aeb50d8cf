"""ChunkedSubprocVecEnv: environments in chunks over processes behave exactly as a DummyVecEnv of
the same environments (layout changes speed, never results), and route attribute and method
calls to the process that holds each environment."""
import numpy as np
import pytest
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv

from fr5_rl.training.train import make_env_factory, make_vec_env
from fr5_rl.training.vec_env import ChunkedSubprocVecEnv, split_evenly, split_with_lighter_first

# Randomisation on, so that every environment's own seeded draws matter.
ENV = {"randomisation": {"enabled": True, "action_latency_steps": [0, 1], "observation_noise_std": 0.002,
                         "physics_dt_choices": [0.005, 0.01]}, "reach": {"max_steps": 20}}


def factories(n_envs, seed=3):
    return [make_env_factory("reach", ENV, seed, rank, None) for rank in range(n_envs)]


def step_alike(chunked, reference, action):
    """Step both vectorised envs; assert identical observations, rewards, dones and infos
    (terminal observations included); the reference's dones and infos."""
    obs_c, rew_c, done_c, info_c = chunked.step(action)
    obs_r, rew_r, done_r, info_r = reference.step(action)
    np.testing.assert_array_equal(obs_c, obs_r)
    np.testing.assert_array_equal(rew_c, rew_r)
    np.testing.assert_array_equal(done_c, done_r)
    for one_c, one_r in zip(info_c, info_r):
        assert one_c.keys() == one_r.keys()
        for key in one_r.keys() - {"terminal_observation", "episode"}:  # episode holds wall times
            assert one_c[key] == one_r[key], key
        if "terminal_observation" in one_r:
            np.testing.assert_array_equal(one_c["terminal_observation"], one_r["terminal_observation"])
    return done_r, info_r


def test_split_evenly_covers_every_index_once_in_near_equal_chunks():
    for n_items in range(1, 12):
        for n_chunks in range(1, n_items + 1):
            chunks = split_evenly(n_items, n_chunks)
            assert [i for chunk in chunks for i in chunk] == list(range(n_items))
            sizes = [len(chunk) for chunk in chunks]
            assert max(sizes) - min(sizes) <= 1 and min(sizes) >= 1
    with pytest.raises(ValueError, match="processes"):
        split_evenly(3, 4)
    with pytest.raises(ValueError):
        split_evenly(3, 0)


def test_split_with_a_lighter_first_chunk_covers_every_index_once():
    assert split_with_lighter_first(16, 2, 1) == [range(0, 7), range(7, 16)]
    assert split_with_lighter_first(16, 3, 1) == [range(0, 4), range(4, 10), range(10, 16)]
    assert split_with_lighter_first(16, 2, 0) == split_evenly(16, 2)
    assert split_with_lighter_first(4, 4, 1) == split_evenly(4, 4)  # a chunk keeps one item
    for n_items in range(1, 12):
        for n_chunks in range(1, n_items + 1):
            for fewer in range(0, 4):
                chunks = split_with_lighter_first(n_items, n_chunks, fewer)
                assert [i for chunk in chunks for i in chunk] == list(range(n_items))
                sizes = [len(chunk) for chunk in chunks]
                assert len(sizes) == n_chunks and min(sizes) >= 1
                assert max(sizes[1:], default=0) - min(sizes[1:], default=0) <= 1
                even_first = len(split_evenly(n_items, n_chunks)[0])
                assert sizes[0] == (n_items if n_chunks == 1 else max(even_first - fewer, 1))
    with pytest.raises(ValueError, match="first_fewer"):
        split_with_lighter_first(8, 2, -1)


def test_chunked_steps_exactly_as_a_dummy_vec_env_through_automatic_resets():
    """Same seeds, same actions: identical observations, rewards, dones, infos and terminal
    observations over several 20-step episodes (so automatic resets happen in every chunk)."""
    n_envs, steps = 5, 70
    reference = DummyVecEnv(factories(n_envs))
    chunked = ChunkedSubprocVecEnv(factories(n_envs), 3, start_method="forkserver")
    try:
        assert chunked.chunks == [range(0, 2), range(2, 3), range(3, 5)]
        assert not chunked.local.venv.has_idle_work  # plain resets: nothing deferred
        reference.seed(11)
        chunked.seed(11)
        np.testing.assert_array_equal(chunked.reset(), reference.reset())
        actions = np.random.default_rng(0).uniform(-1, 1, (steps, n_envs, 7)).astype(np.float32)
        resets = 0
        for action in actions:
            _, infos = step_alike(chunked, reference, action)
            resets += sum("terminal_observation" in info for info in infos)
        assert resets >= 2 * n_envs
        assert len(chunked.reset_infos) == n_envs
    finally:
        chunked.close()
        reference.close()


@pytest.mark.slow  # a curriculum run in worker processes: `make test`, not `make test-fast`
def test_curriculum_starts_prepared_in_idle_time_change_nothing_the_trainer_sees():
    """Grasp with expert-prefixed starts, each environment's next one prepared in a spare while its
    process waits (the workers' and the trainer's chunk's idle time): the same observations,
    rewards, dones and starts as a DummyVecEnv, which prepares every start at its reset."""
    from fr5_rl.training.hyperparameters import ExpertStartSettings

    settings = ExpertStartSettings(max_steps=70, first_reach_back=0.3, promote_at=0.6, window=100, step_back=0.1,
                                   frontier_share=0.5, prepare_ahead=True)
    env = {"grasp": {"max_steps": 85}}  # 15-36 policy steps after a start at 49-70: resets in every chunk
    n_envs = 4
    reference = make_vec_env("grasp", env, n_envs, 5, None, subprocess=True, processes=1, expert_start=settings)
    chunked = make_vec_env("grasp", env, n_envs, 5, None, subprocess=True, processes=2, expert_start=settings)
    try:
        assert isinstance(reference, DummyVecEnv) and isinstance(chunked, ChunkedSubprocVecEnv)
        # Starts prepared ahead: the trainer's own chunk one environment lighter than an even split.
        assert chunked.chunks == [range(0, 1), range(1, 4)]
        assert chunked.local.venv.has_idle_work and len(chunked.local.venv._idle_work) == 1  # through the Monitor
        for venv in (reference, chunked):
            venv.seed(17)
            venv.env_method("set_reach_back", 0.3)
        np.testing.assert_array_equal(chunked.reset(), reference.reset())
        actions = np.random.default_rng(2).uniform(-1, 1, (80, n_envs, 7)).astype(np.float32)
        starts = []
        for action in actions:
            dones, infos = step_alike(chunked, reference, action)
            starts += [info["expert_steps"] for info, done in zip(infos, dones) if done]
        assert len(starts) >= 2 * n_envs and all(49 <= start <= 70 for start in starts)
    finally:
        chunked.close()
        reference.close()


def test_attributes_and_methods_reach_the_right_environment_in_any_order():
    chunked = ChunkedSubprocVecEnv(factories(4), 2, start_method="forkserver")
    try:
        chunked.reset()
        assert chunked.get_attr("control_dt") == [0.02] * 4
        chunked.set_attr("marker", "a", indices=[3, 0])
        chunked.set_attr("marker", "b", indices=[1, 2])
        assert chunked.get_attr("marker", indices=[3, 1, 0, 2]) == ["a", "b", "a", "b"]
        assert chunked.env_is_wrapped(Monitor) == [True] * 4
        assert chunked.has_attr("control_dt") and not chunked.has_attr("no_such_attribute")
        # An error inside a worker is raised here; the worker lives on and answers the next call.
        with pytest.raises(AttributeError):
            chunked.env_method("no_such_method", indices=[3])
        assert chunked.get_attr("marker", indices=[3]) == ["a"]
    finally:
        chunked.close()
    chunked.close()  # a second close is harmless
    assert all(not process.is_alive() for process in chunked.processes)


def test_an_error_in_every_chunk_leaves_the_pipes_in_step():
    """A bad step fails in the trainer's chunk and in the worker's alike: the error is raised
    once all have answered, so the next step reads its own answers, not the failed ones."""
    chunked = ChunkedSubprocVecEnv(factories(4), 2, start_method="forkserver")
    try:
        observations = chunked.reset()
        with pytest.raises(ValueError, match="the action must have shape"):
            chunked.step(np.zeros((4, 3), dtype=np.float32))  # 3 numbers for 7 actuators
        good = np.zeros((4,) + chunked.action_space.shape, dtype=np.float32)
        next_observations, rewards, dones, infos = chunked.step(good)
        assert next_observations.shape == observations.shape and len(infos) == 4
    finally:
        chunked.close()


def test_make_vec_env_picks_the_layout_from_processes():
    one = make_vec_env("reach", ENV, 3, 0, None, subprocess=True, processes=1)
    two = make_vec_env("reach", ENV, 3, 0, None, subprocess=True, processes=2)
    off = make_vec_env("reach", ENV, 3, 0, None, subprocess=False, processes=2)
    try:
        assert isinstance(one, DummyVecEnv) and isinstance(off, DummyVecEnv)
        assert isinstance(two, ChunkedSubprocVecEnv) and len(two.processes) == 1  # + this process
    finally:
        for venv in (one, two, off):
            venv.close()


def test_processes_below_one_refused_before_any_run_directory(tmp_path, capsys):
    from fr5_rl.cli import train

    run_dir = tmp_path / "run"
    assert train.main(["--processes", "0", "--timesteps", "100", "--run-dir", str(run_dir), "--no-progress"]) == 2
    assert "--processes must be at least 1" in capsys.readouterr().err
    assert not run_dir.exists()


FORK_SERVER_SCRIPT = """
import multiprocessing, sys
from fr5_rl.training.fork_server import start_fork_server

def report(queue):
    queue.put(("wave" in sys.modules, "zipapp" in sys.modules))

if __name__ == "__main__":
    start_fork_server(["wave"])
    context = multiprocessing.get_context("forkserver")
    queue = context.Queue()
    worker = context.Process(target=report, args=(queue,))
    worker.start()
    print(queue.get(timeout=60))
    worker.join()
"""


def test_fork_server_workers_start_with_its_modules_imported(tmp_path):
    """A worker forked from the server started by start_fork_server finds the named modules
    imported (done once, in the server), and no others of the kind."""
    import subprocess
    import sys

    script = tmp_path / "fork_server_check.py"
    script.write_text(FORK_SERVER_SCRIPT)
    result = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "(True, False)"
