"""A loopback emulation of the FR5 controller's XML-RPC gripper methods, for the simulator.

On the real cell the gripper is not on ROS: the controller serves the SDK's calls over XML-RPC
(``192.168.58.2:20003``) and the gripper bridge (``fr5_rl.drivers.gripper_bridge``) drives it.
:class:`ControllerEmulator` serves the same gripper methods, with the vendor's argument order and
units, on ``127.0.0.1``, so the bridge runs unchanged in the simulated loop. The simulator reads
what the fingers should do (:meth:`ControllerEmulator.commanded_width`, m) and reports what they
measure (:meth:`ControllerEmulator.set_measured_width`, m).

Every method returns an error code, 0 on success: a bare ``int``, or a list led by the code and
followed by the call's values. Nonzero codes are this emulator's choice (the vendor's table is not
at hand): :data:`ERR_BAD_VALUE` for an argument out of range or a wrong gripper index,
:data:`ERR_NOT_ACTIVATED` for a move before ``ActGripper(index, 1)``. A call with the wrong
number of arguments (e.g. the 6-argument ``MoveGripper`` on an emulator set to accept only the
10-argument form) is an XML-RPC *fault*, not an error code: the controller's XML-RPC layer refuses
a signature it does not know before the method runs. The fault codes (-502 wrong argument count,
-506 no such method) are those a third-party emulation of controller software v3.8.5.1 models;
the vendor does not document them.

No PyBullet and no ROS here: only the standard library and ``fr5_rl.config``.
"""
from __future__ import annotations

import socketserver
import threading
import xmlrpc.client
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Optional, Tuple
from xmlrpc.server import SimpleXMLRPCServer

from ..config import ConfigError, load_robot_spec

#: Error codes (the emulator's choice): an argument out of range / unknown gripper index, and a
#: move before activation.
ERR_BAD_VALUE, ERR_NOT_ACTIVATED = 4, 14
#: XML-RPC fault codes: wrong argument count, unknown method.
FAULT_WRONG_ARITY, FAULT_NO_SUCH_METHOD = -502, -506
#: ``MoveGripper`` argument counts the SDKs use.
MOVE_GRIPPER_FORMS = (6, 10)
#: The manufacturer's rviz panel: tool outputs (DO0, DO1) = (1, 0) closes, (0, 1) opens.
DO_CLOSED, DO_OPEN = (1, 0), (0, 1)


@dataclass(frozen=True)
class ControllerEmulatorSettings:
    """How the emulated controller is configured (the simulator node's parameters).

    :param gripper_index: the gripper number configured on the controller; other indices are refused.
    :param move_gripper_args: the ``MoveGripper`` forms accepted: ``[6]``, ``[10]`` or ``[6, 10]``.
    :param invert_percent: True when 0 % is fully open (the bridge's ``invert_percent`` must match).
    :param position_zero_transient: s after a ``MoveGripper`` during which ``GetGripperCurPosition``
        reads 0 (the field report); 0 turns the quirk off.
    """

    gripper_index: int
    move_gripper_args: List[int]
    invert_percent: bool
    position_zero_transient: float

    def check(self, source: str) -> None:
        """Refuse settings the emulator cannot honour.

        :param source: where the values came from, for the error message.
        :raises ConfigError: naming the first bad key.
        """
        forms = self.move_gripper_args
        if not forms or any(form not in MOVE_GRIPPER_FORMS for form in forms):
            raise ConfigError(f"{source}: 'move_gripper_args' must list 6 and/or 10, got {forms!r}")
        if self.position_zero_transient < 0:
            raise ConfigError(f"{source}: 'position_zero_transient' must be >= 0, got {self.position_zero_transient}")


class _Server(socketserver.ThreadingMixIn, SimpleXMLRPCServer):
    # Threads: a client that hangs up mid-request must not hold up the next one.
    daemon_threads = True

    def handle_error(self, request: Any, client_address: Any) -> None:
        pass  # a client hung up mid-reply (e.g. its timeout): nothing for the simulator to know


class ControllerEmulator:
    """The FR5 controller's gripper methods over XML-RPC on ``127.0.0.1``, in a thread of its own.

    :param settings: the emulated controller's configuration.
    :param port: TCP port to serve on; 0 picks a free one (read :attr:`port` after :meth:`start`).
    :param clock: the simulator's clock (s, monotonic; simulated time works), for the transient 0.
    """

    def __init__(self, settings: ControllerEmulatorSettings, port: int, clock: Callable[[], float]) -> None:
        settings.check("controller emulator")
        self.settings, self.port, self.clock = settings, port, clock
        self.max_width = load_robot_spec().max_opening_width  # m, = 100 %
        self.lock = threading.Lock()
        self.server: Optional[_Server] = None
        self.calls: List[Tuple[float, str, tuple]] = []  # (clock, method, args) of every request
        self.activated = False
        self.fault = 0
        self.tool_do = [0, 0]
        self.commanded: Optional[float] = None  # m
        self.commanded_at = 0.0  # s (clock) the newest command arrived
        self.measured: Optional[float] = None  # m
        self.last_move_at: Optional[float] = None
        # Motion done: each command gets a number; it is done once the simulator, having read
        # that command, reports the fingers still (a report about an older command does not count).
        self.command_seq = self.seen_seq = self.done_seq = 0

    # ------------------------------------------------------------------ the simulator's side
    @property
    def url(self) -> str:
        """``http://127.0.0.1:PORT``: what the bridge's ``controller_url`` should be."""
        return f"http://127.0.0.1:{self.port}"

    def start(self) -> None:
        """Serve on ``127.0.0.1:port`` (the same port again after :meth:`stop`)."""
        server = _Server(("127.0.0.1", self.port), logRequests=False, allow_none=True)
        server.register_instance(self)
        self.port = server.server_address[1]
        self.server = server
        threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.05}, name="fr5_controller_emulator",
                         daemon=True).start()

    def stop(self) -> None:
        """Stop serving and close the socket (the controller is then unreachable)."""
        server, self.server = self.server, None
        if server is not None:
            server.shutdown()
            server.server_close()

    def commanded_width(self) -> Optional[float]:
        """The opening width the fingers should go to (m), None before the first command.

        Calling it marks the newest command as seen by the simulator (see :meth:`set_measured_width`).
        """
        command = self.newest_command()
        return None if command is None else command[1]

    def newest_command(self) -> Optional[Tuple[float, float]]:
        """``(when, width)``: the newest command's arrival (s, this emulator's clock) and the
        opening width it asks for (m); None before the first command. A simulator that catches
        up on late physics steps applies it from its arrival on, not from when it looked.

        Calling it marks the newest command as seen by the simulator (see :meth:`set_measured_width`).
        """
        with self.lock:
            self.seen_seq = self.command_seq
            return None if self.commanded is None else (self.commanded_at, self.commanded)

    def set_measured_width(self, width_m: float, moving: bool) -> None:
        """What the simulated fingers measure, for ``GetGripperCurPosition`` and ``GetGripperMotionDone``.

        :param width_m: opening width between the fingers (m).
        :param moving: the fingers are still moving; False once they stopped (at the target, or on an object).
        """
        with self.lock:
            self.measured = float(width_m)
            if not moving:
                self.done_seq = self.seen_seq

    def set_gripper_fault(self, fault: int) -> None:
        """The gripper fault code the read methods report (0: none).

        :param fault: fault code.
        """
        with self.lock:
            self.fault = int(fault)

    def is_activated(self) -> bool:
        """Whether ``ActGripper(index, 1)`` came after the last reset."""
        with self.lock:
            return self.activated

    def requests(self) -> List[Tuple[str, tuple]]:
        """``(method, args)`` of every request so far, in order."""
        with self.lock:
            return [(method, args) for _, method, args in self.calls]

    # ------------------------------------------------------------------ XML-RPC
    def serve_call(self, method: str, params: tuple) -> Any:
        """One request answered in-process, exactly as over XML-RPC (an in-process bench's
        controller: no socket, no thread, the caller's clock).

        :return: the reply (error code, or a list led by it).
        :raises xmlrpc.client.Fault: an unknown method or a wrong argument count, as the server would.
        """
        return self._dispatch(method, params)

    def _dispatch(self, method: str, params: tuple) -> Any:
        with self.lock:
            self.calls.append((self.clock(), method, tuple(params)))  # refused ones too: tests look for them
            handler = self._methods().get(method)
            if handler is None:
                raise xmlrpc.client.Fault(FAULT_NO_SUCH_METHOD, f"Method '{method}' not defined")
            function, arities = handler
            if len(params) not in arities:
                raise xmlrpc.client.Fault(FAULT_WRONG_ARITY, f"{method} takes {' or '.join(map(str, arities))} "
                                                             f"arguments, got {len(params)}")
            return function(*params)

    def _methods(self) -> Dict[str, Tuple[Callable[..., Any], Tuple[int, ...]]]:
        return {"ActGripper": (self._act_gripper, (2,)),
                "MoveGripper": (self._move_gripper, tuple(self.settings.move_gripper_args)),
                "GetGripperMotionDone": (self._motion_done, (0,)),
                "GetGripperCurPosition": (self._cur_position, (0,)),
                "GetGripperActivateStatus": (self._activate_status, (0,)),
                "SetToolDO": (self._set_tool_do, (4,))}

    # Each handler runs with the lock held and returns the reply.
    def _act_gripper(self, index: Any, act: Any) -> int:
        if index != self.settings.gripper_index or act not in (0, 1):
            return ERR_BAD_VALUE
        self.activated = act == 1
        return 0

    def _move_gripper(self, index: Any, pos: Any, vel: Any, force: Any, max_time: Any, block: Any,
                      *rotary: Any) -> int:
        numbers = (pos, vel, force, max_time, block) + rotary
        if index != self.settings.gripper_index or not all(_is_number(value) for value in numbers):
            return ERR_BAD_VALUE
        if not (0 <= pos <= 100 and 0 <= vel <= 100 and 0 <= force <= 100 and 0 <= max_time <= 30000
                and block in (0, 1)):
            return ERR_BAD_VALUE
        if rotary and rotary[0] != 0:  # type 0: the emulated gripper is a parallel one
            return ERR_BAD_VALUE
        if not self.activated:
            return ERR_NOT_ACTIVATED
        # block 0 (blocking) is answered at once too: the emulator never holds a reply.
        self._command(self._width_of(float(pos)))
        self.last_move_at = self.clock()
        return 0

    def _motion_done(self) -> List[int]:
        return [0, self.fault, 1 if self.done_seq == self.command_seq else 0]

    def _cur_position(self) -> List[int]:
        moved = self.last_move_at
        if self.measured is None or (moved is not None and self.clock() - moved < self.settings.position_zero_transient):
            return [0, self.fault, 0]
        return [0, self.fault, self._percent_of(self.measured)]

    def _activate_status(self) -> List[int]:
        return [0, self.fault, 1 if self.activated else 0]

    def _set_tool_do(self, do_id: Any, status: Any, smooth: Any, block: Any) -> int:
        if do_id not in (0, 1) or any(value not in (0, 1) for value in (status, smooth, block)):
            return ERR_BAD_VALUE
        before = tuple(self.tool_do)
        self.tool_do[do_id] = status
        after = tuple(self.tool_do)
        # Only a whole pair commands: after the first call of a pair the outputs may read (1, 1).
        if after != before and after in (DO_CLOSED, DO_OPEN):
            self._command(0.0 if after == DO_CLOSED else self.max_width)
        return 0

    # ------------------------------------------------------------------ helpers (lock held)
    def _command(self, width: float) -> None:
        self.commanded = width
        self.commanded_at = self.clock()
        self.command_seq += 1

    # The percent <-> width conventions below are the controller's, written apart from the bridge's
    # (fr5_rl.drivers.gripper_decisions) on purpose: a stand-in that shared the bridge's code would
    # agree with any mistake in it.
    def _width_of(self, percent: float) -> float:
        """Opening width (m) for a controller percentage (the bridge's ``invert_percent`` convention)."""
        return self.max_width * ((100.0 - percent) if self.settings.invert_percent else percent) / 100.0

    def _percent_of(self, width: float) -> int:
        """Whole controller percent for an opening width (m), clamped into 0 … 100."""
        percent = min(100, max(0, int(round(100.0 * width / self.max_width))))
        return 100 - percent if self.settings.invert_percent else percent


def _is_number(value: Any) -> bool:
    """An XML-RPC int or double, not a boolean (which XML-RPC also decodes as an int subclass)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)
