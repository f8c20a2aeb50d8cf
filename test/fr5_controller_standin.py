"""A loopback stand-in for the FR5 controller's XML-RPC server (the gripper methods the bridge
calls), shared by the gripper tests and the gripper bridge's rostest."""
from __future__ import annotations

import socketserver
import threading
import time
from typing import Dict, List, Optional, Tuple
from xmlrpc.server import SimpleXMLRPCServer

# The vendor's rviz gripper panel (FR5_FACTS.md): close and open are two SetToolDO calls each.
CLOSE_PAIR = [("SetToolDO", (0, 1, 0, 0)), ("SetToolDO", (1, 0, 0, 0))]
OPEN_PAIR = [("SetToolDO", (0, 0, 0, 0)), ("SetToolDO", (1, 1, 0, 0))]
# Read-only requests (the liveness probe and the position read-back): left out of requests() by default.
READS = ("GetGripperMotionDone", "GetGripperCurPosition")


class _ThreadingXMLRPCServer(socketserver.ThreadingMixIn, SimpleXMLRPCServer):
    # Threads: a delayed (hanging) request must not keep the next one from being answered.
    daemon_threads = True

    def handle_error(self, request, client_address) -> None:
        pass  # the bridge hung up on a delayed request: expected, not worth a traceback


class StandInController:
    """Loopback XML-RPC server playing the FR5 controller.

    Records every request as ``(monotonic time, method, args)``; replies 0 (or ``[0]`` with
    ``list_replies``), or the code set in ``error_codes[method]``; sleeps ``delay`` seconds before
    replying; answers ``GetGripperCurPosition`` with ``position`` (%); ``stop()`` takes it off the network (listening socket closed) and ``start()``
    brings it back on the same port.
    """

    def __init__(self, port: int = 0) -> None:
        self.lock = threading.Lock()
        self.calls: List[Tuple[float, str, tuple]] = []
        self.error_codes: Dict[str, int] = {}
        self.delay = 0.0
        self.list_replies = False
        self.position = 0  # % that GetGripperCurPosition reports
        self.port = port
        self.server: Optional[SimpleXMLRPCServer] = None
        self.start()

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self) -> None:
        server = _ThreadingXMLRPCServer(("127.0.0.1", self.port), logRequests=False, allow_none=True)
        server.register_instance(self)
        self.port = server.server_address[1]
        self.server = server
        threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.02}, daemon=True).start()

    def stop(self) -> None:
        server, self.server = self.server, None
        if server is not None:
            server.shutdown()
            server.server_close()

    def _dispatch(self, method: str, params: tuple):
        with self.lock:
            self.calls.append((time.monotonic(), method, tuple(params)))
            delay, code = self.delay, self.error_codes.get(method, 0)
        if delay:
            time.sleep(delay)
        if method not in ("ActGripper", "MoveGripper", "SetToolDO", "GetGripperMotionDone", "GetGripperCurPosition"):
            raise ValueError(f'method "{method}" is not supported')  # becomes an XML-RPC Fault
        if method == "GetGripperMotionDone":
            return [code, 0, 1]  # [error, fault, status]: no fault, motion done
        if method == "GetGripperCurPosition":
            return [code, 0, self.position]  # [error, fault, position %]
        return [code] if self.list_replies else code

    def requests(self, since: float = 0.0, probes: bool = False) -> List[Tuple[str, tuple]]:
        """(method, args) of the requests recorded from ``since`` on, without probes and read-backs unless asked."""
        with self.lock:
            return [(m, a) for t, m, a in self.calls if t >= since and (probes or m not in READS)]

    def times(self, method: str, since: float = 0.0) -> List[float]:
        with self.lock:
            return [t for t, m, _ in self.calls if m == method and t >= since]
