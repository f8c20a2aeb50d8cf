"""A node's share of the CPU: lower its scheduling priority so the control loop wins a busy machine."""
from __future__ import annotations

import os
from pathlib import Path


def lower_priority(nice: int) -> int:
    """Raise every thread of this process to niceness ``nice`` (0 = as started, 19 = lowest), so
    that on a loaded machine the scheduler runs the nodes at the default niceness first; on an
    idle one the process still gets all the CPU it wants. Threads started later inherit it.

    Linux keeps a niceness per thread (``nice(2)`` changes only the caller's), so each thread
    in ``/proc/self/task`` is set; elsewhere only the process is.

    :param nice: target niceness, 0..19; a process already nicer is left as it is.
    :return: the niceness of the calling thread afterwards.
    :raises ValueError: ``nice`` outside 0..19.
    """
    if not 0 <= nice <= 19:
        raise ValueError(f"niceness must be 0..19 (19 lowest priority), got {nice}")
    tasks = Path("/proc/self/task")
    threads = [int(entry.name) for entry in tasks.iterdir()] if tasks.is_dir() else [0]
    for thread in threads:
        try:
            if os.getpriority(os.PRIO_PROCESS, thread) < nice:
                os.setpriority(os.PRIO_PROCESS, thread, nice)
        except (ProcessLookupError, PermissionError):
            pass  # a thread that ended meanwhile; raising it is always allowed, so no other case
    return os.getpriority(os.PRIO_PROCESS, 0)
