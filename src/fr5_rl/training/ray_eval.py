"""Evaluation spread over a Ray cluster: what ``evaluate.py --ray`` runs.

The seeds are cut into contiguous slices, one Ray task each (spread over the nodes). Every task
runs :func:`fr5_rl.training.evaluation.run_episodes`, the serial evaluation's own code, on its
slice; the records come back sorted by seed, so the result files equal a serial run's. The
model's files travel through Ray's object store: a worker needs this package, not the model
directory. Ray is imported inside functions only.

One episode's physics is not quite independent of the episode before it in the same
environment (PyBullet keeps some state across ``reset``: 10 of 40 reach episodes of the
scripted expert ended up to 0.4 mm apart in a fresh environment, while replaying the one seed
before reproduced all 40 bit for bit). So every slice but the first first replays the seed
before it, as the serial run did, and drops that episode: the outcomes are the serial run's.
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple

from ..deploy.bundle import required_files
from .evaluation import run_episodes
from .ray_compat import import_ray


def seed_slices(seeds: Sequence[int], parts: int) -> List[List[int]]:
    """``seeds`` cut into at most ``parts`` contiguous, non-empty slices of near-equal size."""
    parts = max(1, min(int(parts), len(seeds)))
    size, extra = divmod(len(seeds), parts)
    slices, start = [], 0
    for index in range(parts):
        end = start + size + (1 if index < extra else 0)
        slices.append([int(s) for s in seeds[start:end]])
        start = end
    return [s for s in slices if s]


def evaluate_slice(task: str, env_overrides: Dict[str, Any], seeds: List[int], backend: Optional[str],
                   model_files: Optional[Dict[str, bytes]],
                   warm_up_seed: Optional[int] = None) -> Tuple[str, List[Dict[str, Any]]]:
    """One Ray task: the episodes of ``seeds``; returns (this node's id, the records).

    :param backend: ``torch`` or ``onnx`` for a model, None for the scripted expert.
    :param model_files: the model directory's files (name -> bytes) for ``backend``.
    :param warm_up_seed: an episode run first and dropped: the one the serial run had before ``seeds``.
    """
    import ray

    node_id = ray.get_runtime_context().get_node_id()
    skip = 0 if warm_up_seed is None else 1
    seeds = ([int(warm_up_seed)] if skip else []) + list(seeds)
    if backend is None:
        from ..expert import ScriptedExpert

        def make_actor(env):
            expert = ScriptedExpert(env)
            return expert.act, expert.reset

        return node_id, run_episodes(task, env_overrides, make_actor, seeds)[skip:]
    from ..deploy.policy import load_policy

    with tempfile.TemporaryDirectory(prefix="fr5_rl_eval_model_") as directory:
        for name, data in (model_files or {}).items():
            Path(directory, name).write_bytes(data)
        policy = load_policy(Path(directory), backend)

        def make_policy_actor(env):
            return policy.act, None

        return node_id, run_episodes(task, env_overrides, make_policy_actor, seeds)[skip:]


def run_episodes_on_ray(task: str, env_overrides: Dict[str, Any], seeds: Sequence[int],
                        model_dir: Optional[Path] = None, backend: str = "torch", address: Optional[str] = None,
                        tasks: Optional[int] = None) -> Tuple[List[Dict[str, Any]], List[str]]:
    """The records :func:`run_episodes` would give for ``seeds``, computed by Ray tasks.

    :param model_dir: the model to evaluate; None: the scripted expert.
    :param address: Ray cluster (``auto``, ``HOST:PORT``); None: ``RAY_ADDRESS``, else a local Ray.
        A Ray already initialised in this process is used as it is.
    :param tasks: Ray tasks to cut the seeds into (default: the cluster's CPUs).
    :returns: the records sorted by seed, and the node id of each task.
    :raises ConfigError: Ray is not installed.
    """
    ray, _ = import_ray()
    started = False
    if not ray.is_initialized():
        local = address is None and not os.environ.get("RAY_ADDRESS")
        ray.init(address=address, logging_level="warning", **({"include_dashboard": False} if local else {}))
        started = True
    try:
        files = None
        if model_dir is not None:
            files = {name: (Path(model_dir) / name).read_bytes() for name in required_files(backend)}
        files_ref = ray.put(files)
        parts = tasks or int(ray.cluster_resources().get("CPU", 1))
        remote = ray.remote(num_cpus=1)(evaluate_slice).options(scheduling_strategy="SPREAD")
        slices = seed_slices(list(seeds), parts)
        futures = [remote.remote(task, env_overrides, part, None if model_dir is None else backend, files_ref,
                                 slices[index - 1][-1] if index else None)
                   for index, part in enumerate(slices)]
        outcomes = ray.get(futures)
    finally:
        if started:
            ray.shutdown()
    records = sorted((record for _, part in outcomes for record in part), key=lambda record: record["seed"])
    return records, [node for node, _ in outcomes]
