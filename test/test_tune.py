"""Ray Tune sweeps (tune.py): the search file, the results table, the best config's round trip
through train.py's loader, and, on a two-node Ray cluster on this machine (one CPU per node),
a sweep whose trials run on both nodes, a node lost mid-trial and a killed driver resumed.

Trials are tiny (a few hundred steps, 16-unit networks): the plumbing is tested, not learning.
"""
from __future__ import annotations

import csv
import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from fr5_rl.cli import tune as tune_cli
from fr5_rl.config import ConfigError
from fr5_rl.training.tune.results import sort_rows, write_best_hyperparams
from fr5_rl.training.tune.search_space import check_sampler, to_tune_space, trial_hyperparameters, trial_processes
from fr5_rl.training.tune.settings import build_settings
from fr5_rl.training.algorithms import check_hyperparameters, load_hyperparameters

pytestmark = pytest.mark.slow  # a two-node Ray cluster and sweeps on it: `make test`, not `make test-fast`

REPO = Path(__file__).resolve().parent.parent
MB = 1024 * 1024

TINY_SPACE = """\
base: ppo_reach
trial: {n_envs: 1, timesteps: %(timesteps)d, eval_freq: 256, eval_episodes: 2, target_success: 0.95,
        stop_at_success: false, max_failures: 2}
asha: {grace_period: 512, reduction_factor: 2}
fixed:
  env: {}
  algo_kwargs.n_steps: 128
  algo_kwargs.batch_size: 64
  algo_kwargs.n_epochs: 1
  algo_kwargs.policy_kwargs.net_arch: {pi: [16], vf: [16]}
space:
  algo_kwargs.learning_rate: {loguniform: [0.0001, 0.001]}
  seed: {randint: [0, 1000]}
"""


def tiny_space(tmp_path: Path, timesteps: int = 512) -> Path:
    path = tmp_path / "space.yaml"
    path.write_text(TINY_SPACE % {"timesteps": timesteps}, encoding="utf-8")
    return path


def read_rows(out: Path) -> list:
    return json.loads((out / "results.json").read_text())["trials"]


# ----------------------------------------------------------------------------- pure parts
def test_shipped_search_files_load_and_resolve(tmp_path):
    for algo in ("ppo", "sac"):
        settings = build_settings("reach", algo, 4, "optuna", "asha", tmp_path / algo)
        spec = settings.spec
        assert settings.timesteps == spec.trial.timesteps and settings.n_envs == spec.trial.n_envs
        assert settings.base_hyperparameters == load_hyperparameters(algo, "reach").to_dict()
        assert set(to_tune_space(spec.space, "optuna")) == set(spec.space)


def test_search_space_yaml_becomes_tune_domains():
    from ray import tune as ray_tune
    from ray.tune.search.sample import Categorical, Float, Integer

    space = {"a.lr": {"loguniform": [0.0001, 0.01]}, "a.gamma": {"uniform": [0.9, 0.99]},
             "a.n": {"choice": [64, 128]}, "seed": {"randint": [0, 10]}, "a.q": {"quniform": [0.0, 1.0, 0.25]},
             "a.g": {"grid": [1, 2]}}
    domains = to_tune_space(space, "random")
    assert isinstance(domains["a.lr"], Float) and (domains["a.lr"].lower, domains["a.lr"].upper) == (0.0001, 0.01)
    assert isinstance(domains["a.lr"].get_sampler(), Float._LogUniform)
    assert isinstance(domains["a.gamma"].get_sampler(), Float._Uniform)
    assert isinstance(domains["a.n"], Categorical) and domains["a.n"].categories == [64, 128]
    assert isinstance(domains["seed"], Integer) and (domains["seed"].lower, domains["seed"].upper) == (0, 10)
    assert domains["a.q"].get_sampler().q == 0.25
    assert domains["a.g"] == ray_tune.grid_search([1, 2])
    with pytest.raises(ConfigError, match="grid"):
        to_tune_space({"a.g": {"grid": [1, 2]}}, "optuna")


@pytest.mark.parametrize("spec, message", [
    ({"uniform": [1.0, 0.5]}, "low < high"), ({"loguniform": [0.0, 1.0]}, "low > 0"),
    ({"normal": [0, 1]}, "must be one of"), ({"choice": []}, "non-empty list"),
    ({"uniform": ["a", "b"]}, "needs numbers"), ({"uniform": [0, 1], "choice": [1]}, "must be one of"),
])
def test_bad_samplers_are_refused(spec, message):
    with pytest.raises(ConfigError, match=message):
        check_sampler("algo_kwargs.x", spec, "search.yaml")


def test_trial_hyperparameters_set_dotted_keys_and_refuse_unknown_ones():
    base = load_hyperparameters("ppo", "reach").to_dict()
    hyper = trial_hyperparameters(base, {"algo_kwargs.n_epochs": 3},
                                  {"algo_kwargs.policy_kwargs.log_std_init": -0.7, "seed": 5}, 2, 1000)
    assert hyper["algo_kwargs"]["n_epochs"] == 3 and hyper["algo_kwargs"]["policy_kwargs"]["log_std_init"] == -0.7
    assert hyper["algo_kwargs"]["policy_kwargs"]["net_arch"] == base["algo_kwargs"]["policy_kwargs"]["net_arch"]
    assert (hyper["n_envs"], hyper["n_timesteps"]) == (2, 1000) and "seed" not in hyper
    assert base == load_hyperparameters("ppo", "reach").to_dict()  # the base is not modified
    with pytest.raises(ConfigError, match="not in the hyperparameter file"):
        trial_hyperparameters(base, {}, {"algo_kwarg.gamma": 0.9}, 1, 10)
    with pytest.raises(ConfigError, match="not a mapping"):
        trial_hyperparameters(base, {}, {"n_envs.x": 1}, 1, 10)


def test_trial_processes_default_to_one_per_environment_and_are_capped():
    assert [trial_processes(n, None) for n in (1, 2, 4)] == [1, 2, 4]
    assert [trial_processes(16, p) for p in (1, 3, 40)] == [1, 3, 16]


def test_processes_are_checked_and_saved(tmp_path):
    space = tiny_space(tmp_path)
    assert build_settings("reach", "ppo", 1, "random", "none", tmp_path, space).trial_cpus == 1
    settings = build_settings("reach", "ppo", 1, "random", "none", tmp_path, space, n_envs=4, processes=2)
    assert (settings.n_envs, settings.trial_cpus) == (4, 2)
    with pytest.raises(ConfigError, match="--processes must be at least 1"):
        build_settings("reach", "ppo", 1, "random", "none", tmp_path, space, processes=0)
    space.write_text(space.read_text().replace("n_envs: 1,", "n_envs: 2, processes: 3,"), encoding="utf-8")
    with pytest.raises(ConfigError, match="'trial.processes' must be 1..n_envs"):
        build_settings("reach", "ppo", 1, "random", "none", tmp_path, space)


def row(trial_id, success, steps, to_solve=None, status="finished"):
    return {"trial_id": trial_id, "success": success, "steps": steps, "timesteps_to_solve": to_solve,
            "status": status, "config": {}, "history": []}


def test_results_are_sorted_by_score():
    rows = [row("slow", 1.0, 300, 200, "solved"), row("weak", 0.4, 900), row("broken", 0.0, 10, status="error"),
            row("fast", 1.0, 100, 80, "solved"), row("mid", 0.9, 500), row("mid_cheaper", 0.9, 200)]
    ordered = sort_rows(rows)
    assert [r["trial_id"] for r in ordered] == ["fast", "slow", "mid_cheaper", "mid", "weak", "broken"]
    assert [r["rank"] for r in ordered] == [1, 2, 3, 4, 5, 6]


def test_best_hyperparams_round_trip_through_train_loader(tmp_path):
    settings = build_settings("reach", "ppo", 2, "random", "asha", tmp_path, tiny_space(tmp_path))
    config = {"algo_kwargs.learning_rate": 0.000321, "seed": 17}
    best = {**row("t1", 0.5, 512), "config": config, "seed": 17}
    path = write_best_hyperparams(best, settings, tmp_path / "best_hyperparams.yaml")
    hyper = load_hyperparameters("ppo", "reach", path)
    check_hyperparameters("ppo", hyper, hyper.n_envs, str(path))
    assert hyper.algo_kwargs["learning_rate"] == 0.000321 and hyper.algo_kwargs["n_steps"] == 128
    assert hyper.n_timesteps == load_hyperparameters("ppo", "reach").n_timesteps  # full length, not the budget
    assert hyper.env == {} and hyper.n_envs == 1
    assert "--seed 17" in path.read_text()


def test_resume_needs_an_earlier_experiment(tmp_path, capsys):
    assert tune_cli.main(["--resume", str(tmp_path)]) == 2
    assert "--resume needs the --out directory" in capsys.readouterr().err


def test_a_trial_bigger_than_every_node_is_refused(tmp_path, capsys, cluster):
    code = tune_cli.main(["--space", str(tiny_space(tmp_path)), "--n-envs", "2", "--samples", "1",
                          "--out", str(tmp_path / "out")])
    error = capsys.readouterr().err
    assert code == 2 and "a trial needs 2 CPUs" in error and "--processes 1" in error


# ----------------------------------------------------------------------------- on a 2-node cluster
# The `cluster` fixture (a head and a worker node, one CPU each) is test/conftest.py's.


def node_ids():
    import ray

    return {node["NodeID"] for node in ray.nodes() if node["Alive"]}


def test_sweep_runs_trials_on_both_nodes_and_writes_its_outputs(cluster, tmp_path):
    from fr5_rl.deploy.policy import load_policy

    out = tmp_path / "out"
    # two environments in each one-CPU trial: --processes 1 steps both in the trainer's process
    code = tune_cli.main(["--space", str(tiny_space(tmp_path)), "--samples", "2", "--search", "optuna",
                          "--scheduler", "asha", "--n-envs", "2", "--processes", "1", "--out", str(out)])
    assert code == 0
    rows = read_rows(out)
    assert len(rows) == 2 and [r["rank"] for r in rows] == [1, 2]
    assert {r["node_id"] for r in rows} == node_ids(), "the two trials should run on the two nodes"
    assert all(r["steps"] == 512 and r["status"] == "finished" and r["start_step"] == 0 for r in rows)
    assert all([h[0] for h in r["history"]] == [256, 512] for r in rows)
    with open(out / "results.csv", newline="") as stream:
        table = list(csv.DictReader(stream))
    assert [t["trial_id"] for t in table] == [r["trial_id"] for r in rows]
    assert {"node_id", "success", "steps", "time_to_solve_s", "algo_kwargs.learning_rate", "seed"} <= set(table[0])
    assert (out / "success_vs_steps.png").stat().st_size > 5000
    hyper = load_hyperparameters("ppo", "reach", out / "best_hyperparams.yaml")
    assert math.isclose(hyper.algo_kwargs["learning_rate"], rows[0]["config"]["algo_kwargs.learning_rate"])
    meta = json.loads((out / "best_model" / "meta.json").read_text())
    assert meta["tune"]["trial_id"] == rows[0]["trial_id"] and meta["task"] == "reach" and meta["algo"] == "ppo"
    assert hyper.n_envs == 2
    for backend in ("torch", "onnx"):
        policy = load_policy(out / "best_model", backend, expected_task="reach")
        assert policy.act(__import__("numpy").zeros(23, dtype="float32")).shape == (7,)


def wait_for(predicate, timeout: float, what: str):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.2)
    raise AssertionError(f"timed out after {timeout} s waiting for {what}")


def checkpoints(out: Path):
    return sorted((out / "tune").glob("run_trial_*/checkpoint_*/checkpoints/latest/meta.json"))


def test_trial_on_a_removed_node_resumes_from_its_checkpoint(cluster, tmp_path):
    """The worker node dies mid-trial: Tune retries the trial on the head from its checkpoint."""
    import ray
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

    head_id = cluster.head_node.node_id
    worker = next(node for node in cluster.worker_nodes)

    @ray.remote(num_cpus=1)
    class Hold:  # keeps the head's CPU busy, so that the trial starts on the worker
        def ready(self):
            return True

    hold = Hold.options(scheduling_strategy=NodeAffinitySchedulingStrategy(head_id, soft=False)).remote()
    ray.get(hold.ready.remote())
    out = tmp_path / "out"
    removed = {}

    def registered_step():
        """The older checkpoint's step once two are on disk (Tune may delete it as we read: None)."""
        paths = checkpoints(out)
        try:
            return json.loads(paths[0].read_text())["num_timesteps"] if len(paths) >= 2 else None
        except (OSError, ValueError):
            return None

    def remove_worker_once_a_checkpoint_is_registered():
        # A checkpoint on disk is not yet Tune's: the driver registers it only when the trial's
        # save task returns, after the report. The trial, blocked in its report until then, writes
        # its second checkpoint only after the first is registered; a node lost between the two
        # steps rightly restarts the trial from scratch (seen on CI).
        removed["registered_step"] = wait_for(registered_step, 150, "the trial's second checkpoint")
        cluster.remove_node(worker, allow_graceful=False)
        ray.kill(hold)

    killer = threading.Thread(target=remove_worker_once_a_checkpoint_is_registered, daemon=True)
    killer.start()
    try:
        code = tune_cli.main(["--space", str(tiny_space(tmp_path, timesteps=3072)), "--samples", "1",
                              "--search", "random", "--scheduler", "none", "--out", str(out)])
        killer.join(timeout=5)
        assert code == 0 and removed, "the experiment should finish after losing the worker"
        (trial,) = read_rows(out)
        assert trial["start_step"] >= removed["registered_step"] > 0, \
            "the retried trial should start from its newest registered checkpoint"
        assert trial["node_id"] == head_id and trial["steps"] == 3072
        assert worker.node_id in trial["node_ids"] and head_id in trial["node_ids"]
    finally:
        cluster.add_node(num_cpus=1, object_store_memory=80 * MB)  # the next test gets two nodes again
        cluster.wait_for_nodes()


def state_knows_a_checkpoint(out: Path) -> bool:
    states = sorted((out / "tune").glob("experiment_state-*.json"))
    try:
        return bool(states) and "checkpoint_00" in states[-1].read_text()
    except OSError:
        return False


def test_killed_driver_resumes_with_resume(cluster, tmp_path):
    """tune.py killed mid-sweep (as by Ctrl-C twice or kill -9); --resume finishes the sweep."""
    out = tmp_path / "out"
    env = dict(os.environ, RAY_ADDRESS=cluster.address, PYTHONPATH=f"{REPO / 'src'}{os.pathsep}"
               f"{os.environ.get('PYTHONPATH', '')}")
    driver = subprocess.Popen([sys.executable, str(REPO / "scripts" / "tune.py"), "--space",
                               str(tiny_space(tmp_path, timesteps=1536)), "--samples", "2", "--search", "random",
                               "--scheduler", "none", "--out", str(out)], env=env, cwd=REPO,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        # Killed once Tune's saved experiment state knows a trial checkpoint (Tune saves it every few s).
        wait_for(lambda: state_knows_a_checkpoint(out) or driver.poll() is not None, 120,
                 "Tune's experiment state to record a checkpoint")
        assert driver.poll() is None, "the sweep ended before it could be killed"
        driver.send_signal(signal.SIGKILL)
        driver.wait(timeout=10)
    finally:
        if driver.poll() is None:
            driver.kill()
    assert tune_cli.main(["--resume", str(out)]) == 0
    rows = read_rows(out)
    assert len(rows) == 2 and all(r["steps"] == 1536 for r in rows)
    assert any(r["start_step"] > 0 for r in rows), "a resumed trial should start from its checkpoint"
