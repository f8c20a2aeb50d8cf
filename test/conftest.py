"""Fixtures shared by several test modules."""
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
