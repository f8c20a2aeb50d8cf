"""Client for the FR5 controller's XML-RPC server (the vendor SDK's calls), free of ROS.

The FAIRINO controller serves the SDK's calls over XML-RPC (port 20003). Every call returns an
error code, 0 on success, either bare or as the first element of a list followed by the call's
values. This module knows the transport (a timeout on every request), the error codes and the
vendor's methods with their argument order and units; what to send and when is the gripper
bridge's business (:mod:`fr5_rl.drivers.gripper_bridge`).
"""
from __future__ import annotations

import http.client
import socket
import xmlrpc.client
from dataclasses import dataclass
from typing import Any, Optional, Protocol, Tuple

#: ``ActGripper`` ``act`` values.
GRIPPER_RESET, GRIPPER_ACTIVATE = 0, 1
#: ``MoveGripper`` ``block`` values (the SDK's convention: 0 waits for the motion to end).
BLOCKING, NON_BLOCKING = 0, 1


@dataclass(frozen=True)
class Call:
    """One XML-RPC request: ``method(*args)``, arguments in the vendor's order."""

    method: str
    args: Tuple[int, ...]

    def __str__(self) -> str:
        return f"{self.method}({', '.join(str(arg) for arg in self.args)})"


# ---------------------------------------------------------------------------------------------
# The vendor's methods the gripper uses. Each builds a Call; a client runs it.


def act_gripper(index: int, act: int) -> Call:
    """``ActGripper(index, act)``: reset or activate an electric gripper.

    :param index: the gripper number configured on the controller.
    :param act: :data:`GRIPPER_RESET` (0) or :data:`GRIPPER_ACTIVATE` (1).
    """
    return Call("ActGripper", (index, act))


def move_gripper(index: int, position_percent: int, velocity_percent: int, force_percent: int,
                 max_time_ms: int, block: int) -> Call:
    """``MoveGripper(index, pos, vel, force, max_time, block)``: the 6-argument form.

    :param index: the gripper number configured on the controller.
    :param position_percent: target opening, % of the gripper's range, 0 … 100 (integer: the SDK's type).
    :param velocity_percent: speed, % of the gripper's maximum, 0 … 100.
    :param force_percent: force, % of the gripper's maximum, 0 … 100.
    :param max_time_ms: longest the motion may take (ms), 0 … 30000.
    :param block: :data:`BLOCKING` (0) or :data:`NON_BLOCKING` (1).
    """
    return Call("MoveGripper", (index, position_percent, velocity_percent, force_percent, max_time_ms, block))


def move_gripper_10(index: int, position_percent: int, velocity_percent: int, force_percent: int,
                    max_time_ms: int, block: int, gripper_type: int, rot_num: int, rot_vel: int,
                    rot_torque: int) -> Call:
    """``MoveGripper(index, pos, vel, force, max_time, block, type, rotNum, rotVel, rotTorque)``: the
    10-argument form of newer SDKs; a plain parallel gripper sends the last four as 0.

    :param index: the gripper number configured on the controller.
    :param position_percent: target opening, % of the gripper's range, 0 … 100.
    :param velocity_percent: speed, % of the gripper's maximum, 0 … 100.
    :param force_percent: force, % of the gripper's maximum, 0 … 100.
    :param max_time_ms: longest the motion may take (ms), 0 … 30000.
    :param block: :data:`BLOCKING` (0) or :data:`NON_BLOCKING` (1).
    :param gripper_type: 0 parallel, 1 rotary.
    :param rot_num: rotary gripper: turns (0 for a parallel gripper).
    :param rot_vel: rotary gripper: speed, % (0 for a parallel gripper).
    :param rot_torque: rotary gripper: torque, % (0 for a parallel gripper).
    """
    return Call("MoveGripper", (index, position_percent, velocity_percent, force_percent, max_time_ms, block,
                                gripper_type, rot_num, rot_vel, rot_torque))


def set_tool_do(do_id: int, status: int, smooth: int, block: int) -> Call:
    """``SetToolDO(id, status, smooth, block)``: one digital output of the tool flange.

    :param do_id: output number (0 or 1 on the FR5's tool flange).
    :param status: 0 off, 1 on.
    :param smooth: the SDK's smoothing flag (the manufacturer's panel sends 0).
    :param block: the SDK's blocking flag (the manufacturer's panel sends 0).
    """
    return Call("SetToolDO", (do_id, status, smooth, block))


def get_gripper_motion_done() -> Call:
    """``GetGripperMotionDone() -> (error, fault, status)``: read-only, so also a liveness probe."""
    return Call("GetGripperMotionDone", ())


def get_gripper_cur_position() -> Call:
    """``GetGripperCurPosition() -> (error, fault, position%)`` (SDK >= 2.1.2): the fingers' opening, 0 … 100 %."""
    return Call("GetGripperCurPosition", ())


def get_gripper_activate_status() -> Call:
    """``GetGripperActivateStatus() -> (error, fault, status)``: status 1 once the gripper is activated."""
    return Call("GetGripperActivateStatus", ())


def cur_position_of(values: Tuple[Any, ...]) -> Tuple[int, float]:
    """``(fault, position %)`` from a ``GetGripperCurPosition`` reply's values (after the error code).

    :param values: what :meth:`ControllerClient.call` returned, ``(fault, position)`` on a real controller.
    :raises ControllerRefused: for a reply of another shape (e.g. an SDK older than 2.1.2 answering oddly).
    """
    if (len(values) == 2 and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)
            and isinstance(values[0], int)):
        return values[0], float(values[1])
    raise ControllerRefused(f"GetGripperCurPosition: unexpected values {values!r} (expected [error, fault, position])")


def motion_done_fault(values: Tuple[Any, ...]) -> Optional[int]:
    """The gripper's ``fault`` from a ``GetGripperMotionDone`` reply's values (after the error code).

    :param values: what :meth:`ControllerClient.call` returned, ``(fault, status)`` on a real controller.
    :return: the fault code, or None when the reply carries none.
    """
    return values[0] if values and isinstance(values[0], int) else None


#: The manufacturer's rviz gripper panel: two ``SetToolDO`` per close / open, in this order.
PANEL_CLOSE = (set_tool_do(0, 1, 0, 0), set_tool_do(1, 0, 0, 0))
PANEL_OPEN = (set_tool_do(0, 0, 0, 0), set_tool_do(1, 1, 0, 0))


# ---------------------------------------------------------------------------------------------
# Failures and error codes.


class ControllerUnreachable(Exception):
    """No reply: refused, reset, unroutable, timed out, or not XML-RPC at all.

    :param timed_out: True when the socket timeout expired (the controller may have acted).
    """

    def __init__(self, text: str, timed_out: bool = False) -> None:
        super().__init__(text)
        self.timed_out = timed_out


class ControllerRefused(Exception):
    """The controller replied, but not with success: an error code, a Fault, an odd reply.

    :param code: the controller's error code, or None for a Fault / malformed reply.
    """

    def __init__(self, text: str, code: Optional[int] = None) -> None:
        super().__init__(text)
        self.code = code


def error_code_of(reply: Any) -> Tuple[int, Tuple[Any, ...]]:
    """Split a controller reply into (error code, other values).

    The SDK's calls return either an int or a list whose first element is the error code.

    :param reply: the XML-RPC reply as ``xmlrpc.client`` decoded it.
    :raises ControllerRefused: for any other shape.
    """
    # bool is an int subclass, but a True/False reply is not an error code.
    if isinstance(reply, int) and not isinstance(reply, bool):
        return reply, ()
    if isinstance(reply, (list, tuple)) and reply and isinstance(reply[0], int) and not isinstance(reply[0], bool):
        return reply[0], tuple(reply[1:])
    raise ControllerRefused(f"unexpected reply {reply!r} (expected an error code)")


# ---------------------------------------------------------------------------------------------
# The transport.


class TimeoutTransport(xmlrpc.client.Transport):
    """``xmlrpc.client.Transport`` whose connections time out (ServerProxy takes no timeout).

    :param timeout: seconds for connecting and for each socket read/write.
    """

    def __init__(self, timeout: float) -> None:
        super().__init__()
        self.timeout = timeout

    def make_connection(self, host: Any) -> http.client.HTTPConnection:
        connection = super().make_connection(host)
        connection.timeout = self.timeout  # read by connect(), which runs after this
        return connection


class Controller(Protocol):
    """What a user of the controller needs of it (a :class:`ControllerClient`, or a test double)."""

    def call(self, call: Call) -> Tuple[Any, ...]:
        """Run one request; raise :class:`ControllerUnreachable` or :class:`ControllerRefused` on failure."""


class ControllerClient:
    """The controller's XML-RPC server, with a timeout on every call.

    Not thread-safe: one thread uses it.

    :param url: e.g. ``http://192.168.58.2:20003``.
    :param timeout: seconds per call (connect + reply).
    """

    def __init__(self, url: str, timeout: float) -> None:
        self.url, self.timeout = url, timeout
        self.proxy = self._new_proxy()

    def _new_proxy(self) -> xmlrpc.client.ServerProxy:
        return xmlrpc.client.ServerProxy(self.url, transport=TimeoutTransport(self.timeout), allow_none=True)

    def call(self, call: Call) -> Tuple[Any, ...]:
        """Run one request.

        :param call: the method and its arguments (see :func:`move_gripper` and the others).
        :return: the reply's values after the error code (empty for a bare code).
        :raises ControllerUnreachable: no (usable) reply within the timeout.
        :raises ControllerRefused: a non-zero error code, a Fault or a malformed reply.
        """
        try:
            reply = getattr(self.proxy, call.method)(*call.args)
        except xmlrpc.client.Fault as fault:
            raise ControllerRefused(f"{call} raised XML-RPC fault {fault.faultCode}: {fault.faultString}") from None
        except (socket.timeout, TimeoutError):
            self._reset()
            raise ControllerUnreachable(f"{call}: no reply within {self.timeout:g} s", timed_out=True) from None
        except (OSError, http.client.HTTPException, xmlrpc.client.ProtocolError, xmlrpc.client.ResponseError) as error:
            self._reset()
            raise ControllerUnreachable(f"{call}: {type(error).__name__}: {error}") from None
        code, values = error_code_of(reply)
        if code != 0:
            raise ControllerRefused(f"{call} returned error code {code}", code)
        return values

    def _reset(self) -> None:
        # A half-read connection must not be reused for the next request.
        try:
            self.proxy("close")()
        except Exception:  # pragma: no cover - closing a broken connection may fail too
            pass
        self.proxy = self._new_proxy()
