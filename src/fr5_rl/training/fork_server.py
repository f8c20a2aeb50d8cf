"""Multiprocessing's fork server, started early with the environment workers' imports done in it.

Every worker of :class:`~fr5_rl.training.vec_env.ChunkedSubprocVecEnv` imports PyBullet, the
environments and Stable-Baselines3 (for its ``Monitor``, which brings torch): about a second
of CPU each. Started before the trainer's own imports, the fork server does that once, on
another core while the trainer imports torch, and every worker forked from it starts with
the modules in place. This module imports nothing heavy itself, so that calling it comes first.
"""
from __future__ import annotations

import multiprocessing
from typing import Sequence

#: Modules an environment worker needs (``make_env_factory``'s constructors import them).
WORKER_MODULES = ("fr5_rl.envs", "stable_baselines3.common.monitor")


def start_fork_server(modules: Sequence[str] = WORKER_MODULES) -> None:
    """Start the fork server now (if it is not running yet), importing ``modules`` in it.

    Returns at once: the server imports in its own process. Without this call the server
    starts with the first worker, after the trainer's imports, and each worker imports for
    itself. A server already running keeps its modules (the preload list is read at start).

    :param modules: importable module names; one that fails to import is skipped by the
        server, and the worker then imports (and reports) it itself.
    """
    from multiprocessing import forkserver

    # "__main__" is the server's default preload (the script's own module); keep it.
    multiprocessing.get_context("forkserver").set_forkserver_preload(["__main__", *modules])
    forkserver.ensure_running()
