"""pybullet, imported once for the layer: its C module writes its build time on standard error
at import, on every command that simulates, as if something were wrong; here that line is dropped.
The modules of this layer take ``p`` from here; nothing else imports pybullet."""
import os
import sys


def _import_quietly():
    sys.stderr.flush()
    saved, devnull = os.dup(2), os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        import pybullet
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)
    return pybullet


p = _import_quietly()
