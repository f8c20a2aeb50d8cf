"""Driving the FR5's gripper through the controller's XML-RPC server, free of ROS.

The real FR5's gripper is not on ROS: the controller serves XML-RPC (port 20003) and the
gripper is moved with ``ActGripper`` / ``MoveGripper`` (an electric gripper, *position mode*)
or with two ``SetToolDO`` calls per open/close, as the manufacturer's rviz panel does
(*binary mode*). :class:`GripperBridge` turns a stream of opening widths (m) into those calls:

- :meth:`GripperBridge.submit` only checks and stores the newest width, so a caller (a ROS
  subscriber callback) never waits on the network;
- one worker thread makes every XML-RPC call, at most ``max_call_rate`` per second, always for
  the newest width (a burst of commands becomes one call), and only when the width moved past
  the deadband (position) or across the hysteresis band (binary);
- a controller error code, a timeout or an unreachable controller is reported (throttled) and
  retried with exponential backoff; once the controller answers again the newest state is sent
  again (after ``ActGripper`` in position mode, when ``reactivate_after_reconnect`` is set).

The clock and the controller client can be injected, and :meth:`GripperBridge.poll` runs one
due step on the caller's thread, so tests can drive it without the worker.
"""
from __future__ import annotations

import http.client
import json
import math
import socket
import threading
import time
import xmlrpc.client
from dataclasses import asdict, dataclass
from typing import Any, Callable, Dict, List, Optional, Protocol, Tuple, Union
from urllib.parse import urlparse

from ..config import ConfigError

MODES = ("position", "binary")
OPEN, CLOSED = "open", "closed"

#: ``SetToolDO(id, status, smooth, block)`` pairs of the manufacturer's rviz gripper panel.
BINARY_CALLS = {
    CLOSED: (("SetToolDO", (0, 1, 0, 0)), ("SetToolDO", (1, 0, 0, 0))),
    OPEN: (("SetToolDO", (0, 0, 0, 0)), ("SetToolDO", (1, 1, 0, 0))),
}
#: Read-only call used to tell whether the controller is there while nothing needs sending.
PROBE_METHOD = "GetGripperMotionDone"

Report = Callable[[str, str], None]  # (level: "error" | "warn" | "info", message)


@dataclass(frozen=True)
class GripperBridgeParams:
    """``config/gripper_bridge.yaml``: the gripper bridge node's ~private parameters.

    Widths are metres, times seconds unless the name says ms, percentages 0 … 100.
    """

    controller_url: str
    mode: str
    command_topic: str
    gripper_index: int
    velocity_percent: int
    force_percent: int
    max_time_ms: int
    deadband_percent: int
    invert_percent: bool
    activation_settle: float
    reactivate_after_reconnect: bool
    binary_threshold: float
    binary_hysteresis: float
    max_call_rate: float
    call_timeout: float
    retry_initial: float
    retry_max: float
    probe_period: float
    status_rate: float
    error_log_period: float

    def check(self, source: str) -> None:
        if self.mode not in MODES:
            raise ConfigError(f"{source}: 'mode' must be position or binary, got {self.mode!r}")
        parsed = urlparse(self.controller_url)
        if parsed.scheme != "http" or not parsed.hostname:
            raise ConfigError(f"{source}: 'controller_url' must look like http://HOST:PORT, got {self.controller_url!r}")
        for name in ("velocity_percent", "force_percent"):
            if not 0 <= getattr(self, name) <= 100:
                raise ConfigError(f"{source}: '{name}' must be in 0 … 100, got {getattr(self, name)}")
        if not 0 <= self.max_time_ms <= 30000:
            raise ConfigError(f"{source}: 'max_time_ms' must be in 0 … 30000 (the SDK's range), got {self.max_time_ms}")
        if not 1 <= self.deadband_percent <= 100:
            raise ConfigError(f"{source}: 'deadband_percent' must be in 1 … 100, got {self.deadband_percent}")
        for name in ("max_call_rate", "call_timeout", "retry_initial", "retry_max", "status_rate"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"{source}: '{name}' must be positive, got {getattr(self, name)}")
        if self.retry_max < self.retry_initial:
            raise ConfigError(f"{source}: 'retry_max' ({self.retry_max}) must be >= 'retry_initial' ({self.retry_initial})")
        for name in ("activation_settle", "binary_hysteresis", "probe_period", "error_log_period"):
            if getattr(self, name) < 0:
                raise ConfigError(f"{source}: '{name}' must be >= 0, got {getattr(self, name)}")


# ---------------------------------------------------------------------------------------------
# Pure decisions: no clock, no network.


@dataclass(frozen=True)
class Call:
    """One XML-RPC request: ``method(*args)``."""

    method: str
    args: Tuple[int, ...]

    def __str__(self) -> str:
        return f"{self.method}({', '.join(str(arg) for arg in self.args)})"


def width_to_percent(width: float, max_width: float, invert: bool = False) -> int:
    """The ``MoveGripper`` position for an opening width.

    :param width: opening width (m), already inside 0 … ``max_width``.
    :param max_width: the gripper's largest opening (m), = 100 %.
    :param invert: True when the controller counts 0 % as open.
    :return: whole percent 0 … 100 (the SDK takes integers).
    """
    percent = min(100, max(0, int(round(100.0 * width / max_width))))
    return 100 - percent if invert else percent


def needs_move(target: int, sent: Optional[int], deadband: int) -> bool:
    """Whether a new ``MoveGripper`` is worth sending.

    The end stops are always reached exactly: a deadband must not leave the gripper 1 % short
    of fully closed around an object.

    :param target: percent wanted now.
    :param sent: percent last acknowledged by the controller (None: unknown, e.g. after a reconnect).
    :param deadband: smallest change (percent) that is sent.
    """
    if sent is None:
        return True
    if target == sent:
        return False
    return abs(target - sent) >= deadband or target in (0, 100)


def binary_state(width: float, current: Optional[str], threshold: float, hysteresis: float) -> str:
    """Open or closed for a width, with hysteresis so noise near the threshold does not chatter.

    :param width: opening width (m).
    :param current: the state decided for the previous width (None before the first one).
    :param threshold: width (m) separating closed from open.
    :param hysteresis: half-width (m) of the band around ``threshold`` that keeps ``current``.
    """
    if width < threshold - hysteresis:
        return CLOSED
    if width > threshold + hysteresis:
        return OPEN
    if current is None:  # first command inside the band: the threshold alone decides
        return CLOSED if width < threshold else OPEN
    return current


class Backoff:
    """Exponential retry delays: ``initial``, 2×, 4× … capped at ``maximum`` (s)."""

    def __init__(self, initial: float, maximum: float) -> None:
        self.initial, self.maximum = initial, maximum
        self.failures = 0

    def next_delay(self) -> float:
        """Delay (s) before the next attempt after one more failure."""
        delay = min(self.maximum, self.initial * (2.0 ** self.failures))
        self.failures += 1
        return delay

    def reset(self) -> None:
        self.failures = 0


class ThrottledReport:
    """Passes messages on, at most one per ``period`` (s) for each kind of problem.

    The first message of a kind goes through at once; repeats inside the period are counted
    and the count is added to the next one that goes through.

    :param report: where messages go, ``report(level, text)``.
    :param period: seconds between two messages of one kind (0: no throttling).
    :param clock: monotonic time source (s).
    """

    def __init__(self, report: Report, period: float, clock: Callable[[], float] = time.monotonic) -> None:
        self.report, self.period, self.clock = report, period, clock
        self.lock = threading.Lock()
        self.last: Dict[str, float] = {}
        self.suppressed: Dict[str, int] = {}

    def __call__(self, level: str, kind: str, text: str) -> None:
        now = self.clock()
        with self.lock:
            last = self.last.get(kind)
            if last is not None and now - last < self.period:
                self.suppressed[kind] = self.suppressed.get(kind, 0) + 1
                return
            self.last[kind] = now
            count = self.suppressed.pop(kind, 0)
        self.report(level, text + (f" ({count} more like this in the last {self.period:g} s)" if count else ""))

    def forget(self, kind: str) -> None:
        """Let the next message of ``kind`` through at once (the problem was resolved)."""
        with self.lock:
            self.last.pop(kind, None)
            self.suppressed.pop(kind, None)


# ---------------------------------------------------------------------------------------------
# The controller client.


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


def error_code_of(reply: Any) -> Tuple[int, Tuple[Any, ...]]:
    """Split a controller reply into (error code, other values).

    The SDK's calls return either an int or a list whose first element is the error code.
    :raises ControllerRefused: for any other shape.
    """
    if isinstance(reply, int) and not isinstance(reply, bool):
        return reply, ()
    if isinstance(reply, (list, tuple)) and reply and isinstance(reply[0], int) and not isinstance(reply[0], bool):
        return reply[0], tuple(reply[1:])
    raise ControllerRefused(f"unexpected reply {reply!r} (expected an error code)")


class Controller(Protocol):
    """What the bridge needs of a controller (a :class:`ControllerClient`, or a test double)."""

    def call(self, call: Call) -> Tuple[Any, ...]:
        """Run one request; raise :class:`ControllerUnreachable` or :class:`ControllerRefused` on failure."""


class ControllerClient:
    """The controller's XML-RPC server, with a timeout on every call.

    Not thread-safe: one worker thread uses it.

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


# ---------------------------------------------------------------------------------------------
# The bridge.


@dataclass(frozen=True)
class BridgeStatus:
    """What the bridge is doing, for ``~status`` and tests.

    :param mode: position or binary.
    :param connected: the last request got a reply (False before the first one).
    :param activated: ``ActGripper`` succeeded since the last connection loss (position mode).
    :param desired: what the newest width asks for: percent (position) or open/closed (binary).
    :param last_sent: what the controller last acknowledged (None: nothing, or unknown after a loss).
    :param last_error: the latest failure, "" when the latest request succeeded.
    :param calls: XML-RPC requests made (each SetToolDO counted).
    :param failures: requests that failed.
    :param retry_in: seconds until the next retry, 0 when none is pending.
    :param dropped_inputs: widths refused (NaN / inf).
    :param clamped_inputs: widths clamped into 0 … max opening.
    :param gripper_fault: the ``fault`` of the last ``GetGripperMotionDone`` (position mode), if any.
    """

    mode: str
    controller_url: str
    connected: bool
    activated: bool
    desired: Union[int, str, None]
    last_sent: Union[int, str, None]
    last_error: str
    calls: int
    failures: int
    retry_in: float
    dropped_inputs: int
    clamped_inputs: int
    gripper_fault: Optional[int]

    def to_json(self) -> str:
        return json.dumps(asdict(self), sort_keys=True)


class GripperBridge:
    """Opening widths in, rate-limited XML-RPC gripper calls out, on one worker thread.

    :param params: the node's parameters (mode, rates, timeouts, percentages).
    :param max_opening_width: the gripper's largest opening (m), = 100 %.
    :param report: receives ``(level, message)`` for errors, warnings and recoveries; already
        throttled per kind of problem (``params.error_log_period``).
    :param client: the controller; default a :class:`ControllerClient` on ``params.controller_url``.
    :param clock: monotonic time source (s); inject a fake one with :meth:`poll` in tests.
    """

    def __init__(self, params: GripperBridgeParams, max_opening_width: float, report: Report,
                 client: Optional[Controller] = None, clock: Callable[[], float] = time.monotonic) -> None:
        if not max_opening_width > 0:
            raise ConfigError(f"gripper bridge: max opening width must be positive, got {max_opening_width}")
        if params.mode == "binary" and not (
                0.0 < params.binary_threshold - params.binary_hysteresis
                and params.binary_threshold + params.binary_hysteresis < max_opening_width):
            raise ConfigError(f"gripper bridge: binary_threshold ± binary_hysteresis ({params.binary_threshold:g} ± "
                              f"{params.binary_hysteresis:g} m) must lie inside (0, {max_opening_width:g}) m, "
                              "or one of open/closed could never be commanded")
        self.params, self.max_width, self.clock = params, max_opening_width, clock
        self.client = client if client is not None else ControllerClient(params.controller_url, params.call_timeout)
        self.log = ThrottledReport(report, params.error_log_period, clock)
        self.backoff = Backoff(params.retry_initial, params.retry_max)
        self.min_interval = 1.0 / params.max_call_rate
        self.lock = threading.Condition()
        # ---- shared with submit() under the lock
        self.width: Optional[float] = None  # newest accepted width (m)
        self.binary_desired: Optional[str] = None  # hysteresis state, updated on every width
        self.dropped = self.clamped = 0
        # ---- worker state (written by the worker under the lock, read by status())
        self.connected = False
        self.activated = False
        self.sent: Union[int, str, None] = None
        self.last_error = ""
        self.calls = self.failures = 0
        self.not_before = 0.0  # rate limit / activation settle: no request before this time
        self.retry_at = 0.0  # backoff: no request before this time
        self.last_request_at: Optional[float] = None
        self.lost_at: Optional[float] = None  # when the controller stopped answering
        self.gripper_fault: Optional[int] = None
        self.stopping = False
        self.thread: Optional[threading.Thread] = None

    # ------------------------------------------------------------------ caller side
    def submit(self, width: float) -> Optional[float]:
        """Store a new opening width; returns at once (no network I/O on the caller's thread).

        :param width: opening width (m). NaN/inf is dropped with an error; a width outside
            0 … max opening is clamped with a warning.
        :return: the width that will be acted on (m), or None when dropped.
        """
        try:
            width = float(width)
        except (TypeError, ValueError):
            width = math.nan
        if not math.isfinite(width):
            with self.lock:
                self.dropped += 1
            self.log("error", "nonfinite", f"gripper bridge: dropped non-finite gripper width {width!r}")
            return None
        clamped = min(self.max_width, max(0.0, width))
        if clamped != width:
            with self.lock:
                self.clamped += 1
            self.log("warn", "clamped", f"gripper bridge: width {width:.4f} m outside 0 … {self.max_width:g} m, "
                                        f"clamped to {clamped:g} m")
        with self.lock:
            self.width = clamped
            if self.params.mode == "binary":
                # Hysteresis sees every width, not only those the rate limit lets through.
                self.binary_desired = binary_state(clamped, self.binary_desired, self.params.binary_threshold,
                                                   self.params.binary_hysteresis)
            self.lock.notify_all()
        return clamped

    def status(self) -> BridgeStatus:
        """A consistent snapshot of the bridge's state."""
        with self.lock:
            retry_in = max(0.0, self.retry_at - self.clock()) if self.backoff.failures else 0.0
            return BridgeStatus(mode=self.params.mode, controller_url=self.params.controller_url,
                                connected=self.connected, activated=self.activated, desired=self._desired(),
                                last_sent=self.sent, last_error=self.last_error, calls=self.calls,
                                failures=self.failures, retry_in=round(retry_in, 3), dropped_inputs=self.dropped,
                                clamped_inputs=self.clamped, gripper_fault=self.gripper_fault)

    # ------------------------------------------------------------------ worker thread
    def start(self) -> None:
        """Start the worker thread (it makes every controller request)."""
        self.thread = threading.Thread(target=self._run, name="gripper_bridge", daemon=True)
        self.thread.start()

    def stop(self, timeout: Optional[float] = None) -> None:
        """Stop the worker; waits for a request in flight at most ``timeout`` (default: the call timeout + 1 s)."""
        with self.lock:
            self.stopping = True
            self.lock.notify_all()
        if self.thread is not None:
            self.thread.join(self.params.call_timeout + 1.0 if timeout is None else timeout)

    def _run(self) -> None:
        while True:
            with self.lock:
                while True:
                    if self.stopping:
                        return
                    now = self.clock()
                    step, due = self._next_step(now)
                    if step is not None and due <= now:
                        break
                    # Woken early by submit() (new width) or stop(); otherwise when the step is due.
                    self.lock.wait(None if step is None else due - now)
            self._do(step)

    def poll(self) -> Optional[str]:
        """Run the step that is due now, if any, on the caller's thread (tests, no worker).

        :return: the kind of step run (``activate``, ``move``, ``switch``, ``probe``) or None.
        """
        with self.lock:
            step, due = self._next_step(self.clock())
            if step is None or due > self.clock():
                return None
        self._do(step)
        return step

    # ------------------------------------------------------------------ worker internals (lock held)
    def _desired(self) -> Union[int, str, None]:
        if self.params.mode == "binary":
            return self.binary_desired
        if self.width is None:
            return None
        return width_to_percent(self.width, self.max_width, self.params.invert_percent)

    def _next_step(self, now: float) -> Tuple[Optional[str], float]:
        """What to send next and when: (kind, due time) or (None, 0) when idle for good."""
        earliest = max(self.not_before, self.retry_at)
        desired = self._desired()
        if self.params.mode == "position":
            if not self.activated:
                return "activate", earliest
            if desired is not None and needs_move(desired, self.sent, self.params.deadband_percent):
                return "move", earliest
        elif desired is not None and desired != self.sent:
            return "switch", earliest
        if self.params.probe_period > 0:
            # Connected: a periodic liveness check; lost: the backoff schedule alone.
            if self.connected and self.last_request_at is not None:
                return "probe", max(earliest, self.last_request_at + self.params.probe_period)
            return "probe", earliest
        return None, 0.0

    def _calls_for(self, step: str) -> Tuple[List[Call], Union[int, str, None]]:
        params = self.params
        if step == "activate":
            return [Call("ActGripper", (params.gripper_index, 1))], None
        if step == "probe":
            return [Call(PROBE_METHOD, ())], None
        desired = self._desired()
        if step == "move":
            return [Call("MoveGripper", (params.gripper_index, int(desired), params.velocity_percent,
                                         params.force_percent, params.max_time_ms, 1))], desired
        return [Call(method, args) for method, args in BINARY_CALLS[desired]], desired

    # ------------------------------------------------------------------ one step
    def _do(self, step: str) -> None:
        """Send one step's requests (no lock held during I/O) and record the outcome."""
        with self.lock:
            calls, target = self._calls_for(step)  # the newest width: coalesced here
            started = self.clock()
            self.last_request_at = started
            # Rate limit counts from the start of a request; a slow reply does not add to it.
            self.not_before = started + self.min_interval
        error: Optional[Exception] = None
        values: Tuple[Any, ...] = ()
        made = 0
        for call in calls:
            made += 1
            try:
                values = self.client.call(call)
            except (ControllerUnreachable, ControllerRefused) as failure:
                error = failure
                break
            except Exception as failure:  # an injected client's own bug must not end the worker
                error = ControllerUnreachable(f"{call}: {type(failure).__name__}: {failure}")
                break
        with self.lock:
            self.calls += made
            now = self.clock()
            if error is None:
                self._succeeded(step, target, values, now)
            elif isinstance(error, ControllerRefused):
                self._refused(step, error, now)
            else:
                self._lost(error, now)

    def _answered(self, now: float) -> None:
        """The controller replied (success or not): end a connection loss."""
        if not self.connected and self.lost_at is not None:
            self.log.forget("unreachable")
            self.backoff.reset()
            # Not throttled: a recovery is rare and always worth a line.
            self.log.report("info", f"gripper bridge: controller {self.params.controller_url} answers again "
                                         f"after {now - self.lost_at:.1f} s; resending the newest gripper state")
        self.connected, self.lost_at = True, None

    def _succeeded(self, step: str, target: Union[int, str, None], values: Tuple[Any, ...], now: float) -> None:
        self._answered(now)
        if self.last_error:
            self.log.forget("refused")
        self.last_error = ""
        self.backoff.reset()
        self.retry_at = 0.0
        if step == "activate":
            self.activated = True
            self.sent = None  # activation may move the fingers: the position must be sent again
            self.not_before = max(self.not_before, now + self.params.activation_settle)
        elif step == "probe":
            if self.params.mode == "position" and values and isinstance(values[0], int):
                self.gripper_fault = values[0]
        else:
            self.sent = target

    def _refused(self, step: str, error: ControllerRefused, now: float) -> None:
        self._answered(now)
        if step == "probe":
            # The controller is there. A probe's own error code (e.g. no electric gripper
            # configured, in binary mode) is no reason to back off.
            return
        self.failures += 1
        delay = self.backoff.next_delay()
        self.retry_at = now + delay
        self.last_error = str(error)
        self.log("error", "refused", f"gripper bridge: controller {self.params.controller_url}: {error}; "
                                     f"retrying in {delay:.2f} s")

    def _lost(self, error: ControllerUnreachable, now: float) -> None:
        if self.connected or self.lost_at is None:
            self.lost_at = now
        self.connected = False
        # Unknown what the controller did, or whether it restarted: send the state again once
        # it answers (after activating again, if so configured).
        self.sent = None
        if self.params.reactivate_after_reconnect:
            self.activated = False
        self.failures += 1
        delay = self.backoff.next_delay()
        self.retry_at = now + delay
        self.last_error = str(error)
        what = "timed out" if error.timed_out else "unreachable"
        self.log("error", "unreachable", f"gripper bridge: controller {self.params.controller_url} {what}: {error}; "
                                         f"retrying in {delay:.2f} s (backoff up to {self.params.retry_max:g} s)")
