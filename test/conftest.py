"""Fixtures shared by several test modules."""
import shutil
from pathlib import Path

import pytest

MB = 1024 * 1024


@pytest.fixture(scope="module")
def cluster():
    """A two-node Ray cluster on this machine (a head and a worker, one CPU and 80 MB of object
    store each), with this process connected as the driver; one per test module, torn down after."""
    import ray
    from ray.cluster_utils import Cluster

    node_args = {"num_cpus": 1, "object_store_memory": 80 * MB}
    cluster = Cluster(initialize_head=True, head_node_args={**node_args, "include_dashboard": False})
    cluster.add_node(**node_args)
    cluster.wait_for_nodes()
    ray.init(address=cluster.address, logging_level="warning")
    yield cluster
    ray.shutdown()
    cluster.shutdown()


# ----------------------------------------------------------------------------- a short PPO run
# One 6,000-step PPO reach run for the whole session: test_training and test_fine_tuning start from it.
@pytest.fixture(scope="session")
def ppo_run(tmp_path_factory) -> Path:
    run_dir = tmp_path_factory.mktemp("ppo") / "run"
    from fr5_rl.cli import train

    # 32 environments, the default config's: its 16 steps each make one batch of 512; 6,000 steps
    # end at least one 150-step episode in each
    code = train.main(["--timesteps", "6000", "--n-envs", "32", "--no-subprocess", "--checkpoint-freq", "1000",
                       "--eval-freq", "1000", "--eval-episodes", "2", "--no-progress", "--run-dir", str(run_dir)])
    assert code == 0
    return run_dir


@pytest.fixture
def model_copy(ppo_run, tmp_path) -> Path:
    """A private copy of the run's checkpoint, free to be damaged by the test."""
    target = tmp_path / "model"
    shutil.copytree(ppo_run / "checkpoints" / "latest", target)
    return target


@pytest.fixture
def controller():
    """The loopback stand-in for the FR5 controller's XML-RPC server, stopped after the test."""
    from fr5_controller_standin import StandInController

    stand_in = StandInController()
    yield stand_in
    stand_in.stop()
