"""A node ends with its launch: within a bounded time of a shutdown request, whatever its threads
are doing, and when the process that started it dies.

rospy turns SIGINT and SIGTERM into a shutdown request and leaves the ending to the node's own
loops; a thread blocked elsewhere (a service call, a lock, a C extension) keeps the process alive
after roslaunch has gone, and a roslaunch killed hard (``timeout -k``, CI) never asks at all. Every
node of the package starts through :func:`init_node`, which covers both.
"""
from __future__ import annotations

import ctypes
import os
import signal
import sys
import threading

import rospy

# After a shutdown request a node has this long (s) to end by itself before it is ended.
SHUTDOWN_GRACE_S = 2.0
_PR_SET_PDEATHSIG = 1  # <linux/prctl.h>


def exit_after(seconds: float) -> threading.Timer:
    """End this process (exit status 0) ``seconds`` from now unless it has ended by then: the
    streams are flushed, nothing else runs (``os._exit``)."""
    def end() -> None:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        os._exit(0)

    timer = threading.Timer(seconds, end)
    timer.daemon = True
    timer.start()
    return timer


def die_with_parent(signal_number: int = signal.SIGTERM) -> bool:
    """Ask Linux to send ``signal_number`` to this process when its parent (roslaunch, or the
    shell of ``rosrun``) dies; False where the call is not available (not Linux)."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(_PR_SET_PDEATHSIG, int(signal_number), 0, 0, 0) != 0:
            return False
    except (OSError, AttributeError):
        return False
    if os.getppid() == 1:  # the parent died before the call: the signal will never come
        os.kill(os.getpid(), signal_number)
    return True


def init_node(name: str, **kwargs) -> None:
    """``rospy.init_node`` for a node that ends with its launch (see the module's text)."""
    die_with_parent()
    rospy.init_node(name, **kwargs)
    rospy.on_shutdown(lambda: exit_after(SHUTDOWN_GRACE_S))
