"""The gripper bridge's logic: a stream of opening widths to the FR5 controller, free of ROS.

The real FR5's gripper is not on ROS: the controller serves XML-RPC (the client and the vendor's
methods: :mod:`fr5_rl.drivers.fr5_xmlrpc`) and the gripper is moved with ``ActGripper`` /
``MoveGripper`` (an electric gripper, *position mode*) or with two ``SetToolDO`` calls per
open/close, as the manufacturer's rviz panel does (*binary mode*). :class:`GripperBridge` turns
a stream of opening widths (m) into those calls:

- :meth:`GripperBridge.submit` only checks and stores the newest width, so a caller (a ROS
  subscriber callback) never waits on the network;
- one worker thread makes every XML-RPC call, at most ``max_call_rate`` per second, always for
  the newest width (a burst of commands becomes one call), and only when the width moved past
  the deadband (position) or across the hysteresis band (binary);
- a controller error code, a timeout or an unreachable controller is reported (throttled) and
  retried with exponential backoff; once the controller answers again the newest state is sent
  again (after ``ActGripper(index, 0)`` then ``ActGripper(index, 1)`` in position mode, when
  ``reactivate_after_reconnect`` is set);
- in position mode the fingers are read back with ``GetGripperCurPosition`` at ``readback_rate``
  (outside the command rate limit); the controller's transient 0 right after a ``MoveGripper`` is
  ignored for ``zero_debounce`` s, and each accepted reading goes to ``on_reading`` as a
  :class:`GripperReading` (width in m);
- a read-back older than ``readback_max_age`` holds the next ``MoveGripper`` until a read lands
  past the transient (one lost to it is tried again ``readback_retry`` later): a policy that
  streams a slightly different width every call period would otherwise keep every read inside
  the transient, and the opening it observes, and the detector's tracker uses, would stand still
  for as long as the stream lasts (the rehearsal's place timeouts, stop 65);
- ``on_fault`` hears whenever "the gripper cannot act on a width now" changes: the controller is
  unreachable (or not heard yet) or reports a gripper fault, or, in position mode, the gripper is
  not activated or its activation has not settled (``activation_settle``). A policy that holds on
  the fault therefore does not start before the fingers can follow it.

The clock and the controller client can be injected, and :meth:`GripperBridge.poll` runs one
due step on the caller's thread, so tests can drive it without the worker.
"""
from __future__ import annotations

import json
import math
import threading
import time
from dataclasses import asdict, dataclass
from typing import Any, Callable, List, Optional, Tuple, Union

from ..config import ConfigError
from ..gripper import needs_move, percent_to_width, width_to_percent
from .fr5_xmlrpc import (
    GRIPPER_ACTIVATE, GRIPPER_RESET, NON_BLOCKING, PANEL_CLOSE, PANEL_OPEN, Call, Controller, ControllerClient,
    ControllerRefused, ControllerUnreachable, act_gripper, cur_position_of, get_gripper_cur_position,
    get_gripper_motion_done, motion_done_fault, move_gripper, move_gripper_10,
)
from .gripper_bridge_params import GripperBridgeParams
from .gripper_decisions import CLOSED, OPEN, Backoff, Report, ThrottledReport, binary_state, transient_zero

#: Binary mode: the manufacturer's rviz panel's ``SetToolDO`` pair for each state.
BINARY_CALLS = {CLOSED: PANEL_CLOSE, OPEN: PANEL_OPEN}


@dataclass(frozen=True)
class GripperReading:
    """One accepted ``GetGripperCurPosition`` read-back.

    :param width: opening width between the fingers (m); each finger is at ``width / 2``.
    :param percent: the controller's raw position (%, before ``invert_percent``).
    :param fault: the gripper's fault code in that reply (0: none).
    :param stamp: the bridge's clock when the request was sent (s).
    """

    width: float
    percent: float
    fault: int
    stamp: float


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
    :param gripper_fault: the ``fault`` of the last ``GetGripperMotionDone`` / ``GetGripperCurPosition``
        (position mode), if any.
    :param fault: what the fault topic says: the gripper cannot act on a width now (the controller
        is unreachable or reports a gripper fault; position mode: not activated, or settling).
    :param measured_width: the latest accepted read-back (m), None before the first.
    :param readings: read-backs accepted.
    :param ignored_zero_readings: transient 0 readings ignored right after a move.
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
    fault: bool
    measured_width: Optional[float]
    readings: int
    ignored_zero_readings: int

    def to_json(self) -> str:
        """The fields as a JSON object (``~status``)."""
        return json.dumps(asdict(self), sort_keys=True)


class GripperBridge:
    """Opening widths in, rate-limited XML-RPC gripper calls out, on one worker thread.

    :param params: the node's parameters (mode, rates, timeouts, percentages).
    :param max_opening_width: the gripper's largest opening (m), = 100 %.
    :param report: receives ``(level, message)`` for errors, warnings and recoveries; already
        throttled per kind of problem (``params.error_log_period``).
    :param client: the controller; default a :class:`ControllerClient` on ``params.controller_url``.
    :param clock: monotonic time source (s); inject a fake one with :meth:`poll` in tests.
    :param on_reading: called with each accepted :class:`GripperReading`, on the worker's thread
        (no lock held); must not block.
    :param on_fault: called with the new value of :attr:`BridgeStatus.fault` each time it changes,
        on the worker's thread (no lock held); it starts True (nothing heard from the controller yet).
    """

    def __init__(self, params: GripperBridgeParams, max_opening_width: float, report: Report,
                 client: Optional[Controller] = None, clock: Callable[[], float] = time.monotonic,
                 on_reading: Optional[Callable[[GripperReading], None]] = None,
                 on_fault: Optional[Callable[[bool], None]] = None) -> None:
        if not max_opening_width > 0:
            raise ConfigError(f"gripper bridge: max opening width must be positive, got {max_opening_width}")
        if params.mode == "binary" and not (
                0.0 < params.binary_threshold - params.binary_hysteresis
                and params.binary_threshold + params.binary_hysteresis < max_opening_width):
            raise ConfigError(f"gripper bridge: binary_threshold ± binary_hysteresis ({params.binary_threshold:g} ± "
                              f"{params.binary_hysteresis:g} m) must lie inside (0, {max_opening_width:g}) m, "
                              "or one of open/closed could never be commanded")
        self.params, self.max_width, self.clock = params, max_opening_width, clock
        self.on_reading, self.on_fault = on_reading, on_fault
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
        self.reset_at: Optional[float] = None  # when ActGripper(index, 0) succeeded since the last loss
        self.activated = False
        self.ready_at: Optional[float] = None  # position mode: when the activation has settled
        self.sent: Union[int, str, None] = None
        self.last_error = ""
        self.calls = self.failures = 0
        self.not_before = 0.0  # rate limit / activation settle: no request before this time
        self.retry_at = 0.0  # backoff: no request before this time
        self.last_request_at: Optional[float] = None
        self.lost_at: Optional[float] = None  # when the controller stopped answering
        self.started_at = clock()
        self.ever_answered = False  # a controller not up yet at start-up is no fault worth an error
        self.gripper_fault: Optional[int] = None
        self.fault_reported = True  # what on_fault last heard (nothing heard from the controller: a fault)
        self.last_move_at: Optional[float] = None  # when the latest MoveGripper was sent
        self.last_read_at: Optional[float] = None
        self.measured: Optional[GripperReading] = None
        self.read_refused = False  # the newest read-back was refused (e.g. an SDK without it)
        self.readings = self.ignored_zeros = 0
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
                                clamped_inputs=self.clamped, gripper_fault=self.gripper_fault,
                                fault=self._fault_active(self.clock()),
                                measured_width=None if self.measured is None else round(self.measured.width, 6),
                                readings=self.readings, ignored_zero_readings=self.ignored_zeros)

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
                    fault_changed = self._fault_change(now)
                    step, due = self._next_step(now)
                    if fault_changed is not None or (step is not None and due <= now):
                        break
                    # Woken early by submit() (new width) or stop(); otherwise when the step is
                    # due or the activation settles (the fault clears without a request).
                    wake = [t for t in (due if step is not None else None, self._settles_at(now)) if t is not None]
                    self.lock.wait(min(wake) - now if wake else None)
            if fault_changed is not None:
                self._tell_fault(fault_changed)
                continue
            self._do(step)

    def poll(self) -> Optional[str]:
        """Run the step that is due now, if any, on the caller's thread (tests, no worker).

        :return: the kind of step run (``reset``, ``activate``, ``move``, ``switch``, ``read``, ``probe``) or None.
        """
        with self.lock:
            fault_changed = self._fault_change(self.clock())
            step, due = self._next_step(self.clock())
        if fault_changed is not None:
            self._tell_fault(fault_changed)
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

    def _fault_active(self, now: float) -> bool:
        """The fault topic's value: the gripper cannot act on a width now. The controller is
        unreachable (or not heard yet) or reports a gripper fault; in position mode also before
        ``ActGripper`` succeeded and until ``activation_settle`` after it, when a ``MoveGripper``
        would not be sent yet (the real gripper may still be moving through its activation).

        :param now: the clock's time (s).
        """
        if not self.connected or self.gripper_fault:
            return True
        return self.params.mode == "position" and (not self.activated or self.ready_at is None or now < self.ready_at)

    def _settles_at(self, now: float) -> Optional[float]:
        """When the activation settles (s), if that is still to come; None otherwise."""
        return self.ready_at if self.activated and self.ready_at is not None and self.ready_at > now else None

    def _fault_change(self, now: float) -> Optional[bool]:
        """The fault's new value if it differs from what ``on_fault`` last heard (recorded as heard), else None."""
        fault = self._fault_active(now)
        if fault == self.fault_reported:
            return None
        self.fault_reported = fault
        return fault

    def _tell_fault(self, fault: bool) -> None:
        """``on_fault`` (no lock held: a slow publisher must not hold up submit() or status())."""
        if self.on_fault is not None:
            self.on_fault(fault)

    def _command_step(self, earliest: float) -> Tuple[Optional[str], float]:
        """The next command (reset, activate, move, switch) and when it is due, or (None, 0).

        :param earliest: the rate limit's and the backoff's earliest time (s).
        """
        desired = self._desired()
        if self.params.mode == "position":
            if not self.activated:
                if self.reset_at is None:  # the vendor's example resets before it activates
                    return "reset", earliest
                return "activate", max(earliest, self.reset_at + self.params.reset_settle)
            if desired is not None and needs_move(desired, self.sent, self.params.deadband_percent):
                return "move", earliest
        elif desired is not None and desired != self.sent:
            return "switch", earliest
        return None, 0.0

    def _read_due(self) -> Optional[float]:
        """When the next ``GetGripperCurPosition`` is due (s), None when no read-back runs now.

        Reads keep their own rate, outside ``max_call_rate``: they must not delay a command.
        """
        rate = self.params.readback_rate
        if self.params.mode != "position" or rate <= 0 or not (self.connected and self.activated):
            return None
        if self.last_read_at is None:
            return self.retry_at
        return max(self.retry_at, self.last_read_at + 1.0 / rate)

    def _reading_stale(self, now: float) -> bool:
        """Whether the newest accepted read-back is older than ``readback_max_age`` (s) while
        read-backs work: then a move waits for a fresh one (:meth:`_next_step`). Never before the
        first accepted reading, nor while the controller refuses the read: a move must not wait on
        a read that cannot come.

        :param now: the clock's time (s).
        """
        max_age = self.params.readback_max_age
        return (max_age > 0 and self.measured is not None and not self.read_refused
                and now - self.measured.stamp > max_age)

    def _next_step(self, now: float) -> Tuple[Optional[str], float]:
        """What to send next and when: (kind, due time) or (None, 0) when idle for good.

        A command wins over a read due at the same time, except a move while the read-back is
        stale (:meth:`_reading_stale`): the read goes first.

        :param now: the clock's time (s).
        """
        earliest = max(self.not_before, self.retry_at)
        command, command_due = self._command_step(earliest)
        read_due = self._read_due()
        if command == "move" and read_due is not None and self._reading_stale(now):
            # The move waits on a fresh read: try soon, not a whole read period after the last.
            retry = min(self.params.readback_retry, 1.0 / self.params.readback_rate)
            return "read", min(read_due, max(self.retry_at, (self.last_read_at or 0.0) + retry))
        if command is not None and (read_due is None or command_due <= read_due):
            return command, command_due
        if read_due is not None:
            return "read", read_due
        if self.params.probe_period > 0:
            # Connected: a periodic liveness check; lost: the backoff schedule alone.
            if self.connected and self.last_request_at is not None:
                return "probe", max(earliest, self.last_request_at + self.params.probe_period)
            return "probe", earliest
        return None, 0.0

    def _calls_for(self, step: str) -> Tuple[List[Call], Union[int, str, None]]:
        """The requests of one step and what they make the controller hold (None: no target)."""
        params = self.params
        if step == "reset":
            return [act_gripper(params.gripper_index, GRIPPER_RESET)], None
        if step == "activate":
            return [act_gripper(params.gripper_index, GRIPPER_ACTIVATE)], None
        if step == "probe":
            # Read-only: tells whether the controller is there while nothing needs sending.
            return [get_gripper_motion_done()], None
        if step == "read":
            return [get_gripper_cur_position()], None
        desired = self._desired()
        if step == "move":
            # Non-blocking: a blocking MoveGripper would hold the worker for the whole motion.
            args = (params.gripper_index, int(desired), params.velocity_percent, params.force_percent,
                    params.max_time_ms, NON_BLOCKING)
            if params.move_gripper_args == 10:
                return [move_gripper_10(*args, 0, 0, 0, 0)], desired  # a parallel gripper: no rotation
            return [move_gripper(*args)], desired
        return list(BINARY_CALLS[desired]), desired

    # ------------------------------------------------------------------ one step
    def _do(self, step: str) -> None:
        """Send one step's requests (no lock held during I/O) and record the outcome.

        :param step: ``reset``, ``activate``, ``move``, ``switch``, ``read`` or ``probe``.
        """
        with self.lock:
            calls, target = self._calls_for(step)  # the newest width: coalesced here
            started = self.clock()
            self.last_request_at = started
            if step == "read":
                self.last_read_at = started
            else:
                # Rate limit counts from the start of a request; a slow reply does not add to it.
                self.not_before = started + self.min_interval
            if step == "move":
                self.last_move_at = started  # the transient 0 follows the request
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
        reading: Optional[Tuple[int, float]] = None
        if error is None and step == "read":
            try:
                reading = cur_position_of(values)
            except ControllerRefused as odd:
                error = odd
        accepted: Optional[GripperReading] = None
        with self.lock:
            self.calls += made
            now = self.clock()
            if error is None:
                self._succeeded(step, target, values, now)
                if reading is not None:
                    accepted = self._read(reading, started)
            elif isinstance(error, ControllerRefused):
                self._refused(step, error, now)
            else:
                self._lost(error, now)
            fault_changed = self._fault_change(now)
        # Callbacks outside the lock: a slow publisher must not hold up submit() or status().
        if accepted is not None and self.on_reading is not None:
            self.on_reading(accepted)
        if fault_changed is not None:
            self._tell_fault(fault_changed)

    def _read(self, reading: Tuple[int, float], stamp: float) -> Optional[GripperReading]:
        """Record a ``GetGripperCurPosition`` reply; returns the reading unless it is the transient 0.

        :param reading: ``(fault, position %)`` of the reply.
        :param stamp: the clock's time when the request was sent (s).
        """
        fault, percent = reading
        self.gripper_fault = fault
        self.read_refused = False
        if transient_zero(percent, stamp, self.last_move_at, self.params.zero_debounce):
            self.ignored_zeros += 1
            return None
        width = percent_to_width(percent, self.max_width, self.params.invert_percent)
        self.measured = GripperReading(width=width, percent=percent, fault=fault, stamp=stamp)
        self.readings += 1
        return self.measured

    def _answered(self, now: float) -> None:
        """The controller replied (success or not): end a connection loss.

        :param now: the clock's time (s) when the reply came.
        """
        if not self.connected and self.lost_at is not None:
            self.log.forget("unreachable")
            self.backoff.reset()
            # Not throttled: a recovery is rare and always worth a line.
            self.log.report("info", f"gripper bridge: controller {self.params.controller_url} answers "
                                    f"{'again ' if self.ever_answered else ''}after {now - self.lost_at:.1f} s; "
                                    "resending the newest gripper state")
        self.connected, self.lost_at, self.ever_answered = True, None, True

    def _succeeded(self, step: str, target: Union[int, str, None], values: Tuple[Any, ...], now: float) -> None:
        """Every request of ``step`` returned 0.

        :param step: the step's kind.
        :param target: what the controller now holds (percent or open/closed; None for the other steps).
        :param values: the last reply's values after its error code.
        :param now: the clock's time (s) when the reply came.
        """
        self._answered(now)
        if self.last_error:
            self.log.forget("refused")
        self.last_error = ""
        self.backoff.reset()
        self.retry_at = 0.0
        if step == "reset":
            self.reset_at = now
        elif step == "activate":
            self.activated = True
            self.sent = None  # activation may move the fingers: the position must be sent again
            self.ready_at = now + self.params.activation_settle
            self.not_before = max(self.not_before, self.ready_at)
        elif step == "probe":
            fault = motion_done_fault(values)
            if self.params.mode == "position" and fault is not None:
                self.gripper_fault = fault
        elif step in ("move", "switch"):
            self.sent = target  # a read (recorded by _read) says nothing about what was sent

    def _refused(self, step: str, error: ControllerRefused, now: float) -> None:
        """The controller replied with an error code, a Fault or a malformed reply: back off (not for a probe).

        :param step: the step's kind.
        :param error: the refusal.
        :param now: the clock's time (s) when the reply came.
        """
        self._answered(now)
        if step == "read":
            # The controller is there; e.g. an SDK older than 2.1.2 lacks GetGripperCurPosition.
            # Reads go on at their own rate, without backoff, and no move waits on them; the log
            # is throttled.
            self.read_refused = True
            self.log("warn", "read", f"gripper bridge: read-back refused: {error} (readback_rate: 0 turns it off)")
            return
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
        """No reply: mark the controller lost, forget what it holds, back off.

        :param error: the failure.
        :param now: the clock's time (s) when the request failed.
        """
        if self.connected or self.lost_at is None:
            self.lost_at = now
        self.connected = False
        # Unknown what the controller did, or whether it restarted: send the state again once
        # it answers (after activating again, if so configured).
        self.sent = None
        if self.params.reactivate_after_reconnect:
            self.activated, self.reset_at = False, None
        self.failures += 1
        delay = self.backoff.next_delay()
        self.retry_at = now + delay
        self.last_error = str(error)
        what = "timed out" if error.timed_out else "unreachable"
        if not self.ever_answered and now - self.started_at < self.params.startup_grace:
            # Launched together, the controller (or its emulation) may simply not be up yet.
            self.log("info", "not_up_yet", f"gripper bridge: waiting for the controller {self.params.controller_url} "
                                            f"({what} so far); retrying in {delay:.2f} s")
            return
        self.log("error", "unreachable", f"gripper bridge: controller {self.params.controller_url} {what}: {error}; "
                                         f"retrying in {delay:.2f} s (backoff up to {self.params.retry_max:g} s)")
