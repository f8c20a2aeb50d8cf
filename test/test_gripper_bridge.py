"""The gripper bridge (fr5_rl.drivers.gripper_bridge) and the controller's XML-RPC client
(fr5_rl.drivers.fr5_xmlrpc) against a loopback stand-in for the FR5 controller's XML-RPC server:
what the bridge sends in each mode, how often, and what it does when the controller returns
error codes, hangs, or goes away and comes back.

Every timing the bridge decides (rate limit, backoff, activation settle, probe period, log
throttling) is checked on the bridge's injected clock, a :class:`FakeClock` that only the test
advances, with :meth:`GripperBridge.poll` running each step on the test's thread: no assertion
depends on how fast the machine is. Real time only bounds waits for things that happen at once
(a deadlock guard) and the socket timeout, which is the operating system's.

:class:`StandInController` (test/fr5_controller_standin.py) is also used by the rostest
(test/rostest/test_gripper_bridge_node.py); the client's own tests are in test_fr5_xmlrpc.py.
"""
from __future__ import annotations

import dataclasses
import json
import math
import threading
import time
from typing import Any, Callable, Dict, List, Tuple

import pytest

from fr5_controller_standin import CLOSE_PAIR, OPEN_PAIR, StandInController
from fr5_rl.config import ConfigError, load_robot_spec, load_typed, typed
from fr5_rl.drivers.fr5_xmlrpc import (
    Call, ControllerClient, ControllerRefused,
)
from fr5_rl.drivers.gripper_bridge import GripperBridge
from fr5_rl.drivers.gripper_bridge_params import GripperBridgeParams
from fr5_rl.drivers.gripper_decisions import Backoff, ThrottledReport, binary_state
from fr5_rl.gripper import needs_move, width_to_percent

MAX_WIDTH = load_robot_spec().max_opening_width  # 0.08 m


# ----------------------------------------------------------------------------- helpers
TICK = 0.001  # s: the fake clock's step, finer than every interval the tests configure
# A step falls due on the first tick at or after its time; float rounding may make that the next tick.
WITHIN_A_TICK = 1.5 * TICK


def make_params(**overrides) -> GripperBridgeParams:
    """config/gripper_bridge.yaml with fast test timings, then ``overrides``."""
    # No read-back here: these tests count the commands; test_gripper_bridge_emulator.py reads back.
    fast = dict(max_call_rate=50.0, call_timeout=0.2, retry_initial=0.05, retry_max=0.2, probe_period=0.0,
                activation_settle=0.0, reset_settle=0.0, readback_rate=0.0, error_log_period=0.0, status_rate=10.0,
                startup_grace=0.0)
    return dataclasses.replace(load_typed(GripperBridgeParams, "gripper_bridge"), **{**fast, **overrides})


class Events:
    """Collects the bridge's reports: ``(level, text)``."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.items: List[Tuple[str, str]] = []

    def __call__(self, level: str, text: str) -> None:
        with self.lock:
            self.items.append((level, text))

    def matching(self, level: str, fragment: str) -> List[str]:
        with self.lock:
            return [text for lvl, text in self.items if lvl == level and fragment in text]


class FakeClock:
    """The bridge's injected clock (s): it stands still until the test advances it."""

    def __init__(self, start: float = 100.0) -> None:
        self.now = start

    def __call__(self) -> float:
        return self.now

    def advance(self, seconds: float) -> None:
        self.now = round(self.now + seconds, 9)  # no drift over thousands of ticks


class Recorder:
    """A controller client that records ``(fake time, method, args)`` of each request, then makes it."""

    def __init__(self, client: Any, clock: FakeClock) -> None:
        self.client, self.clock = client, clock
        self.made: List[Tuple[float, str, tuple]] = []

    def call(self, call: Call) -> Tuple[Any, ...]:
        self.made.append((self.clock(), call.method, call.args))
        return self.client.call(call)

    def times(self, method: str) -> List[float]:
        return [t for t, m, _ in self.made if m == method]


class Driven:
    """A bridge without its worker: the test advances the fake clock and runs each due step."""

    def __init__(self, params: GripperBridgeParams, client: Any, clock: FakeClock, **callbacks: Any) -> None:
        self.params, self.clock, self.events = params, clock, Events()
        self.recorder = Recorder(client, clock)
        self.bridge = GripperBridge(params, MAX_WIDTH, report=self.events, client=self.recorder, clock=clock,
                                    **callbacks)  # on_reading, on_fault

    def _poll_now(self, ran: List[Tuple[float, str]]) -> None:
        for _ in range(10):  # the rate limit allows one step per instant; more means it is broken
            step = self.bridge.poll()
            if step is None:
                return
            ran.append((self.clock.now, step))
        pytest.fail(f"steps keep falling due at t={self.clock.now}: {ran[-10:]}")

    def run_for(self, seconds: float) -> List[Tuple[float, str]]:
        """Advance the clock by ``seconds``, running every step that falls due; returns (time, step)."""
        ran: List[Tuple[float, str]] = []
        end = round(self.clock.now + seconds, 9)
        self._poll_now(ran)
        while self.clock.now < end:
            self.clock.advance(TICK)
            self._poll_now(ran)
        return ran

    def run_until(self, predicate: Callable[[], bool], limit: float, what: str) -> float:
        """Advance the clock until ``predicate`` holds; returns the clock seconds it took, fails
        the test after ``limit`` clock seconds."""
        start, ran = self.clock.now, []
        while True:
            self._poll_now(ran)
            elapsed = round(self.clock.now - start, 9)
            if predicate():
                return elapsed
            if elapsed >= limit:
                pytest.fail(f"{what}: not within {limit} s on the bridge's clock; steps run: {ran[-10:]}")
            self.clock.advance(TICK)


class ScriptedController:
    """An in-process controller: records ``(fake time, call)``; replies ``replies[method]`` (values
    after the error code, or an exception to raise), ``()`` for a method not listed."""

    def __init__(self, clock: FakeClock) -> None:
        self.clock = clock
        self.made: List[Tuple[float, Call]] = []
        self.replies: Dict[str, Any] = {}

    def call(self, call: Call) -> Tuple[Any, ...]:
        self.made.append((self.clock(), call))
        reply = self.replies.get(call.method, ())
        if isinstance(reply, Exception):
            raise reply
        return reply


def move(percent: int, params: GripperBridgeParams) -> Tuple[str, tuple]:
    return ("MoveGripper", (params.gripper_index, percent, params.velocity_percent, params.force_percent,
                            params.max_time_ms, 1))


def activate(params: GripperBridgeParams) -> Tuple[str, tuple]:
    return ("ActGripper", (params.gripper_index, 1))


def reset(params: GripperBridgeParams) -> Tuple[str, tuple]:
    return ("ActGripper", (params.gripper_index, 0))


def activation(params: GripperBridgeParams) -> List[Tuple[str, tuple]]:
    """The vendor's example: reset, then activate."""
    return [reset(params), activate(params)]



@pytest.fixture
def drive():
    """Factory: a :class:`Driven` bridge on a fake clock, talking XML-RPC to ``controller``."""

    def make(controller: StandInController, **overrides) -> Driven:
        params = make_params(controller_url=controller.url, **overrides)
        return Driven(params, ControllerClient(params.controller_url, params.call_timeout), FakeClock())

    return make


# ----------------------------------------------------------------------------- parameters
def test_parameter_file_loads_and_bad_values_are_refused():
    params = load_typed(GripperBridgeParams, "gripper_bridge")
    assert params.controller_url == "http://192.168.58.2:20003" and params.mode in ("position", "binary")
    good = dataclasses.asdict(params)
    for key, value, fragment in [("mode", "pneumatic", "'mode'"), ("controller_url", "192.168.58.2:20003", "controller_url"),
                                 ("velocity_percent", 150, "velocity_percent"), ("max_time_ms", 40000, "max_time_ms"),
                                 ("deadband_percent", 0, "deadband_percent"), ("call_timeout", 0.0, "call_timeout"),
                                 ("retry_max", 0.01, "retry_max"), ("probe_period", -1.0, "probe_period")]:
        with pytest.raises(ConfigError, match=fragment):
            typed(GripperBridgeParams, {**good, key: value}, "test")
    with pytest.raises(ConfigError, match="binary_threshold"):  # the open state could never be reached
        GripperBridge(make_params(mode="binary", binary_threshold=0.078), MAX_WIDTH, report=Events())


def test_parameters_have_no_defaults_in_code():
    """config/gripper_bridge.yaml is the one place the defaults live: every field is required."""
    fields = dataclasses.fields(GripperBridgeParams)
    assert all(f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING for f in fields)
    good = dataclasses.asdict(load_typed(GripperBridgeParams, "gripper_bridge"))
    assert set(good) == {f.name for f in fields}
    with pytest.raises(ConfigError, match="missing key 'call_timeout'"):
        typed(GripperBridgeParams, {k: v for k, v in good.items() if k != "call_timeout"}, "test")


# ----------------------------------------------------------------------------- pure decisions
def test_width_to_percent_and_deadband():
    assert [width_to_percent(w, MAX_WIDTH) for w in (0.0, 0.02, 0.04, 0.0792, 0.08)] == [0, 25, 50, 99, 100]
    assert width_to_percent(0.02, MAX_WIDTH, invert=True) == 75
    assert needs_move(50, None, 2)  # nothing known: send
    assert not needs_move(51, 50, 2) and not needs_move(50, 50, 2)
    assert needs_move(52, 50, 2) and needs_move(48, 50, 2)
    assert needs_move(100, 99, 5) and needs_move(0, 1, 5)  # the end stops are always reached


def test_binary_state_has_hysteresis():
    threshold, band = 0.04, 0.005
    states, state = [], None
    for width in (0.07, 0.038, 0.042, 0.0355, 0.0349, 0.044, 0.0449, 0.0451, 0.036):
        state = binary_state(width, state, threshold, band)
        states.append(state)
    assert states == ["open", "open", "open", "open", "closed", "closed", "closed", "open", "open"]
    assert binary_state(0.039, None, threshold, band) == "closed" and binary_state(0.041, None, threshold, band) == "open"


def test_backoff_doubles_up_to_the_cap_and_resets():
    backoff = Backoff(0.05, 0.3)
    assert [backoff.next_delay() for _ in range(5)] == pytest.approx([0.05, 0.1, 0.2, 0.3, 0.3])
    backoff.reset()
    assert backoff.next_delay() == pytest.approx(0.05)


def test_throttled_report_passes_the_first_and_counts_repeats():
    clock = FakeClock(0.0)
    out = []
    report = ThrottledReport(lambda level, text: out.append((level, text)), 5.0, clock=clock)
    for _ in range(4):
        report("error", "lost", "controller lost")
    report("warn", "clamped", "clamped")  # another kind is not held back
    assert out == [("error", "controller lost"), ("warn", "clamped")]
    clock.advance(4.9)
    report("error", "lost", "controller lost")  # still inside the period
    assert len(out) == 2
    clock.advance(0.2)
    report("error", "lost", "controller lost")
    assert out[-1] == ("error", "controller lost (4 more like this in the last 5 s)")
    report.forget("lost")
    report("error", "lost", "again")
    assert out[-1] == ("error", "again")


# ----------------------------------------------------------------------------- position mode
def test_position_mode_activates_once_then_moves_past_the_deadband(controller, drive):
    run = drive(controller, deadband_percent=2)
    bridge, params = run.bridge, run.params
    bridge.submit(0.04)
    run.run_until(lambda: len(controller.requests()) >= 3, 1.0, "ActGripper 0, 1 + MoveGripper")
    assert controller.requests() == activation(params) + [move(50, params)]

    def settle_then_requests():
        run.run_for(5 / params.max_call_rate)  # several call slots: anything due is sent
        return controller.requests()[3:]

    bridge.submit(0.0408)  # 51 %: inside the deadband
    assert settle_then_requests() == []
    bridge.submit(0.0416)  # 52 %: 2 % from the last sent
    run.run_until(lambda: len(controller.requests()) >= 4, 1.0, "MoveGripper 52")
    bridge.submit(0.0792)  # 99 %
    run.run_until(lambda: len(controller.requests()) >= 5, 1.0, "MoveGripper 99")
    bridge.submit(0.08)  # 100 %: 1 % only, but an end stop
    run.run_until(lambda: len(controller.requests()) >= 6, 1.0, "MoveGripper 100")
    bridge.submit(0.0796)  # rounds to 100 %: nothing new
    assert settle_then_requests() == [move(52, params), move(99, params), move(100, params)]
    status = bridge.status()
    assert status.connected and status.activated and status.last_sent == 100 and status.calls == 6
    assert status.failures == 0 and status.last_error == "" and run.events.matching("error", "") == []


def test_burst_is_rate_limited_and_the_newest_width_wins(controller, drive):
    run = drive(controller, max_call_rate=20.0, deadband_percent=1)
    bridge, params = run.bridge, run.params
    run.run_until(lambda: bridge.status().activated, 1.0, "ActGripper 0, 1")
    start = run.clock.now
    widths = [0.08 * ((i * 37) % 100) / 100 for i in range(99)] + [0.03]  # jumping around, last 0.03 m
    stale = []  # MoveGripper targets that were not the newest width at the time they were sent
    for width in widths:
        bridge.submit(width)
        newest = width_to_percent(width, MAX_WIDTH)
        made = len(run.recorder.made)
        run.run_for(0.002)
        stale += [a[1] for _, m, a in run.recorder.made[made:] if m == "MoveGripper" and a[1] != newest]
    run.run_until(lambda: bridge.status().last_sent == 38, 1.0, "the last width (38 %) to be sent")
    run.run_for(3 / params.max_call_rate)
    moves = run.recorder.times("MoveGripper")
    allowed = math.floor(round((moves[-1] - start) * params.max_call_rate, 6)) + 1
    assert 1 <= len(moves) <= allowed, f"{len(moves)} MoveGripper in {moves[-1] - start:.3f} s at {params.max_call_rate} Hz"
    assert len(moves) < 20  # 100 commands coalesced
    gaps = [round(b - a, 9) for a, b in zip(moves, moves[1:])]
    assert all(gap >= 1 / params.max_call_rate for gap in gaps), gaps  # exact on the bridge's clock
    assert stale == []
    assert controller.requests()[-1] == move(38, params)


def test_submit_and_status_never_wait_on_a_request_in_flight():
    """The worker thread is inside a request that only ends once submit() and status() have
    returned on this thread: if either waited for the request, it would never end in time."""
    entered, release = threading.Event(), threading.Event()
    outcome: Dict[str, bool] = {}
    clock = FakeClock()

    class HangingController:
        def call(self, call: Call) -> Tuple[Any, ...]:
            if call == Call("ActGripper", (1, 0)):
                clock.advance(1.0)  # the reset is answered at once; the activation's call slot comes due
            if call == Call("ActGripper", (1, 1)):
                entered.set()
                outcome["released"] = release.wait(10.0)  # False: nobody released it (deadlock)
            return ()

    bridge = GripperBridge(make_params(), MAX_WIDTH, report=Events(), client=HangingController(), clock=clock)
    bridge.start()
    try:
        assert entered.wait(10.0), "the worker made no request"
        assert bridge.submit(0.06) == pytest.approx(0.06)
        assert bridge.status().desired == 75 and bridge.status().activated is False  # the request is still out
        release.set()
    finally:
        release.set()
        bridge.stop(timeout=11.0)
    assert outcome == {"released": True}
    assert bridge.status().activated


@pytest.mark.parametrize("list_replies", [False, True], ids=["int_reply", "list_reply"])
def test_error_code_is_reported_and_retried_with_growing_backoff(controller, drive, list_replies):
    controller.list_replies = list_replies
    controller.error_codes["MoveGripper"] = 14
    run = drive(controller, retry_initial=0.05, retry_max=0.4)
    bridge, params = run.bridge, run.params
    bridge.submit(0.02)
    run.run_until(lambda: bridge.status().failures >= 4, 2.0, "4 refused MoveGripper attempts")
    status = bridge.status()
    assert status.connected and "error code 14" in status.last_error and status.failures == 4
    assert status.last_sent is None and status.retry_in == pytest.approx(0.4)  # the 4th delay: 0.05 × 2³
    assert run.events.matching("error", "error code 14")
    attempts = run.recorder.times("MoveGripper")
    gaps = [b - a for a, b in zip(attempts, attempts[1:])]
    assert gaps == pytest.approx([0.05, 0.1, 0.2], abs=WITHIN_A_TICK), gaps
    del controller.error_codes["MoveGripper"]
    retry = run.run_until(lambda: bridge.status().last_sent == 25, 1.0, "success once the code is 0")
    assert retry == pytest.approx(0.4, abs=WITHIN_A_TICK)  # the retry due, not sooner
    assert bridge.status().last_error == "" and controller.requests()[-1] == move(25, params)
    assert controller.requests().count(activate(params)) == 1  # the link never dropped


def test_the_worker_clears_the_fault_when_the_activation_settles(controller):
    """On the real clock, with nothing to send or read: the worker wakes for the settle alone."""
    params = make_params(controller_url=controller.url, activation_settle=0.3)
    heard: List[Tuple[float, bool]] = []
    bridge = GripperBridge(params, MAX_WIDTH, report=Events(),
                           on_fault=lambda fault: heard.append((time.monotonic(), fault)))
    started = time.monotonic()
    bridge.start()
    try:
        deadline = started + 10.0  # a guard against a hang, not a measurement
        while not heard and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        bridge.stop()
    assert [fault for _, fault in heard] == [False], f"the fault never cleared: {bridge.status()}"
    assert heard[0][0] - started >= params.activation_settle
    assert controller.requests() == activation(params)  # no request was needed to clear it


def test_backoff_schedule_and_activation_settle_on_a_fake_clock():
    """The exact retry times, cap included, with an in-process controller."""
    clock = FakeClock(99.9)  # the activation, one 10 Hz call slot after the reset, at 100.0 s: no float drift
    client = ScriptedController(clock)
    params = make_params(retry_initial=0.1, retry_max=0.5, max_call_rate=10.0, activation_settle=1.0)
    bridge = GripperBridge(params, MAX_WIDTH, report=Events(), client=client, clock=clock)
    assert bridge.poll() == "reset"
    clock.advance(1 / params.max_call_rate)
    assert bridge.poll() == "activate"
    bridge.submit(0.04)
    clock.advance(0.99)
    assert bridge.poll() is None  # activation_settle (1 s) not over
    clock.advance(0.01)
    client.replies["MoveGripper"] = ControllerRefused("MoveGripper returned error code 3", 3)
    assert bridge.poll() == "move"
    retries = []
    while len(retries) < 5:
        clock.advance(0.01)
        if bridge.poll() == "move":
            retries.append(clock.now)
    attempts = [t for t, c in client.made if c.method == "MoveGripper"]
    assert [round(b - a, 6) for a, b in zip(attempts, attempts[1:])] == [0.1, 0.2, 0.4, 0.5, 0.5]
    del client.replies["MoveGripper"]
    clock.advance(0.5)
    assert bridge.poll() == "move" and bridge.status().last_sent == 50 and bridge.status().last_error == ""
    clock.advance(0.1)
    bridge.submit(0.0)
    assert bridge.poll() == "move"  # backoff reset by the success: only the 10 Hz limit applies
    assert bridge.status().last_sent == 0
    assert [c for _, c in client.made][:3] == [Call("ActGripper", (params.gripper_index, 0)),
                                               Call("ActGripper", (params.gripper_index, 1)),
                                               Call("MoveGripper", (params.gripper_index, 50, params.velocity_percent,
                                                                    params.force_percent, params.max_time_ms, 1))]


def test_the_fault_holds_until_the_activation_has_settled_on_a_fake_clock():
    """A gripper that is answered but not activated, or still settling, cannot act on a width:
    the fault stays true until activation_settle is over, and then clears by itself, without a
    request (no read-back, no probe, no width here)."""
    clock = FakeClock(100.0)
    client = ScriptedController(clock)
    heard: List[Tuple[float, bool]] = []
    params = make_params(reset_settle=1.0, activation_settle=2.0)
    bridge = GripperBridge(params, MAX_WIDTH, report=Events(), client=client, clock=clock,
                           on_fault=lambda fault: heard.append((clock.now, fault)))
    assert bridge.poll() == "reset" and bridge.status().connected and bridge.status().fault
    clock.advance(1.0)
    assert bridge.poll() == "activate" and bridge.status().activated
    assert bridge.status().fault and heard == []  # activated, not settled
    clock.advance(1.999)
    assert bridge.poll() is None and heard == []
    clock.advance(0.001)
    assert bridge.poll() is None  # nothing to send: the clear needs no request
    assert heard == [(103.0, False)] and not bridge.status().fault
    assert [c.method for _, c in client.made] == ["ActGripper", "ActGripper"]


def test_binary_mode_has_no_activation_to_wait_for():
    clock = FakeClock(100.0)
    heard: List[bool] = []
    bridge = GripperBridge(make_params(mode="binary", activation_settle=2.0), MAX_WIDTH, report=Events(),
                           client=ScriptedController(clock), clock=clock, on_fault=heard.append)
    bridge.submit(0.0)
    assert bridge.poll() == "switch" and heard == [False]


def test_timeout_is_an_error_and_the_newest_width_follows_once_the_controller_answers(controller, drive):
    run = drive(controller, call_timeout=0.2, retry_initial=0.05, retry_max=0.2)
    bridge, events, params = run.bridge, run.events, run.params
    bridge.submit(0.04)
    run.run_until(lambda: bridge.status().last_sent == 50, 1.0, "first move")
    controller.delay = 3.0  # the controller hangs, far beyond call_timeout
    bridge.submit(0.06)
    run.run_until(lambda: events.matching("error", "timed out"), 0.1, "the timeout error")
    assert len(controller.times("MoveGripper")) == 2  # the hanging request did reach it
    status = bridge.status()
    assert status.connected is False and "no reply within 0.2 s" in status.last_error and status.last_sent is None
    for i in range(20):  # widths keep coming while the controller is lost
        bridge.submit(0.02 + 0.001 * i)
    controller.delay = 0.0
    back = time.monotonic()
    recover = run.run_until(lambda: bridge.status().last_sent == 49, 1.0, "recovery")  # newest: 0.039 m
    after = controller.requests(since=back)
    assert after == activation(params) + [move(49, params)], after
    assert events.matching("info", "answers again")
    # The first retry (the reset) comes after retry_initial; the activation and the move one call slot each after it.
    assert recover == pytest.approx(params.retry_initial + 2 / params.max_call_rate, abs=2 * WITHIN_A_TICK)


@pytest.mark.parametrize("mode", ["position", "binary"])
def test_controller_gone_and_back_resends_the_newest_state(controller, drive, mode):
    run = drive(controller, mode=mode, probe_period=0.1, retry_initial=0.05, retry_max=0.2)
    bridge, events, params = run.bridge, run.events, run.params
    bridge.submit(0.07)
    first = activation(params) + [move(88, params)] if mode == "position" else OPEN_PAIR
    run.run_until(lambda: controller.requests() == first, 1.0, "the first state")
    run.run_for(0.25)  # idle: only probes
    assert controller.requests() == first and len(run.recorder.times("GetGripperMotionDone")) == 2
    controller.stop()  # mid-run, while idle: the liveness probe must notice
    detect = run.run_until(lambda: not bridge.status().connected, 1.0, "the loss to be noticed")
    assert detect <= params.probe_period + WITHIN_A_TICK  # by the next probe
    bridge.submit(0.01)  # a new state while the controller is away
    run.run_for(0.5)  # retries 0.05, 0.1, 0.2 s after the loss, then every 0.2 s
    status = bridge.status()
    assert status.failures == 4 and "unreachable" in events.matching("error", "unreachable")[0]
    assert status.last_sent is None and status.desired == (12 if mode == "position" else "closed")
    controller.start()  # same port
    back = time.monotonic()
    recover = run.run_until(lambda: bridge.status().last_sent is not None, 1.0, "recovery")
    # By the next retry (at most retry_max away), plus a call slot each for the activation and the move.
    assert recover <= params.retry_max + (2 / params.max_call_rate if mode == "position" else 0.0) + 2 * WITHIN_A_TICK
    resent = controller.requests(since=back)
    expected = activation(params) + [move(12, params)] if mode == "position" else CLOSE_PAIR
    assert resent == expected
    assert bridge.status().connected and bridge.status().last_error == ""
    print(f"\n{mode}: loss noticed after {detect:.3f} s (probe every {params.probe_period} s), recovered "
          f"{recover:.3f} s after the controller came back (backoff cap {params.retry_max} s), bridge's clock")


def test_a_controller_not_up_yet_at_start_is_waited_for_in_info_lines_then_an_error(controller, drive):
    """Launched together, the controller (here: its stand-in) may come up after the bridge: inside
    ~startup_grace that is said as info, and its first answer is no "again"; a controller that has
    never answered once the grace is over is an error."""
    controller.stop()
    run = drive(controller, startup_grace=0.5, retry_initial=0.05, retry_max=0.1)
    bridge, events = run.bridge, run.events
    bridge.submit(0.04)
    run.run_for(0.3)
    assert events.matching("info", "waiting for the controller") and not events.matching("error", "")
    controller.start()
    run.run_until(lambda: bridge.status().connected, 1.0, "the controller's first answer")
    assert events.matching("info", "answers after") and not events.matching("info", "answers again")
    assert not events.matching("error", "")

    controller.stop()
    late = drive(controller, startup_grace=0.2, retry_initial=0.05, retry_max=0.1)
    late.bridge.submit(0.04)
    late.run_for(0.6)
    assert late.events.matching("error", "unreachable")


def test_reactivation_can_be_turned_off(controller, drive):
    run = drive(controller, reactivate_after_reconnect=False, probe_period=0.05)
    bridge, params = run.bridge, run.params
    bridge.submit(0.04)
    run.run_until(lambda: bridge.status().last_sent == 50, 1.0, "first move")
    controller.stop()
    run.run_until(lambda: not bridge.status().connected, 1.0, "the loss")
    controller.start()
    back = time.monotonic()
    run.run_until(lambda: bridge.status().last_sent == 50, 1.0, "the resend")
    assert controller.requests(since=back) == [move(50, params)]


def test_probe_reads_the_gripper_fault_and_a_refused_probe_is_no_failure():
    clock = FakeClock()
    client = ScriptedController(clock)
    client.replies["GetGripperMotionDone"] = (5, 1)  # (fault, status) after the error code
    run = Driven(make_params(probe_period=0.5), client, clock)
    run.run_for(1.2)
    slot = 1 / run.params.max_call_rate  # reset, then activate one call slot later; probes count from there
    assert [(round(t - 100.0, 6), c.method) for t, c in client.made] == [
        (0.0, "ActGripper"), (slot, "ActGripper"), (slot + 0.5, "GetGripperMotionDone"),
        (slot + 1.0, "GetGripperMotionDone")]
    assert run.bridge.status().gripper_fault == 5 and run.bridge.status().connected

    # Binary mode on a controller without an electric gripper: the probe's error code still
    # proves the controller is there, so no backoff, and the next probe comes on schedule.
    clock = FakeClock()
    client = ScriptedController(clock)
    client.replies["GetGripperMotionDone"] = ControllerRefused("GetGripperMotionDone() returned error code 14", 14)
    run = Driven(make_params(mode="binary", probe_period=0.5), client, clock)
    run.run_for(1.2)
    assert [round(t - 100.0, 6) for t, _ in client.made] == [0.0, 0.5, 1.0]
    status = run.bridge.status()
    assert status.connected and status.failures == 0 and status.last_error == "" and status.retry_in == 0.0
    assert status.gripper_fault is None and run.events.items == []

    # An injected client's own bug counts as a lost controller, and the bridge goes on.
    client.replies["GetGripperMotionDone"] = RuntimeError("bug in a client")
    run.run_until(lambda: not run.bridge.status().connected, 1.0, "the failed probe")
    status = run.bridge.status()
    assert "RuntimeError: bug in a client" in status.last_error and status.failures == 1
    assert status.retry_in == pytest.approx(run.params.retry_initial)
    assert [step for _, step in run.run_for(run.params.retry_initial)] == ["probe"]  # retried on the backoff


# ----------------------------------------------------------------------------- binary mode
def test_binary_mode_sends_the_pairs_in_order_without_chatter(controller, drive):
    run = drive(controller, mode="binary", binary_threshold=0.04, binary_hysteresis=0.005)
    bridge, params = run.bridge, run.params

    def quiet_after(widths: List[float]) -> List[Tuple[str, tuple]]:
        count = len(controller.requests())
        for width in widths:
            bridge.submit(width)
            run.run_for(1.5 / params.max_call_rate)  # each width gets its own call slot
        return controller.requests()[count:]

    bridge.submit(0.07)
    run.run_until(lambda: len(controller.requests()) == 2, 1.0, "open pair")
    assert quiet_after([0.038, 0.042, 0.0355, 0.0445, 0.036]) == []  # noise inside 0.035 … 0.045 m
    bridge.submit(0.03)
    run.run_until(lambda: len(controller.requests()) == 4, 1.0, "close pair")
    assert quiet_after([0.041, 0.044, 0.036, 0.0449]) == []
    bridge.submit(0.05)
    run.run_until(lambda: len(controller.requests()) == 6, 1.0, "open pair")
    # Close then, within one call slot, a width inside the band: the band keeps "closed".
    bridge.submit(0.01)
    bridge.submit(0.04)
    run.run_until(lambda: len(controller.requests()) == 8, 1.0, "close pair")
    run.run_for(3 / params.max_call_rate)
    assert controller.requests() == OPEN_PAIR + CLOSE_PAIR + OPEN_PAIR + CLOSE_PAIR
    assert bridge.status().last_sent == "closed" and bridge.status().calls == 8
    assert "ActGripper" not in [m for m, _ in controller.requests(probes=True)]


def test_binary_pair_half_done_is_resent_whole(controller, drive):
    controller.error_codes["SetToolDO"] = 9
    run = drive(controller, mode="binary")
    bridge = run.bridge
    bridge.submit(0.0)
    run.run_until(lambda: len(controller.requests()) >= 2, 1.0, "two refused attempts")
    assert set(controller.requests()) == {CLOSE_PAIR[0]}  # the second call never follows a failed first
    del controller.error_codes["SetToolDO"]
    run.run_until(lambda: bridge.status().last_sent == "closed", 1.0, "the close pair")
    assert controller.requests()[-2:] == CLOSE_PAIR and run.events.matching("error", "error code 9")


# ----------------------------------------------------------------------------- bad inputs
def test_bad_widths_are_dropped_or_clamped(controller, drive):
    run = drive(controller, error_log_period=5.0)
    bridge, events, params = run.bridge, run.events, run.params
    run.run_until(lambda: bridge.status().activated, 1.0, "activation")
    for bad in (math.nan, math.inf, -math.inf, "abc"):
        assert bridge.submit(bad) is None
    run.run_for(5 / params.max_call_rate)
    assert controller.requests() == activation(params)  # nothing sent for them
    assert len(events.matching("error", "non-finite")) == 1  # throttled: one line for the four
    assert bridge.status().dropped_inputs == 4 and bridge.status().desired is None
    assert bridge.submit(-0.01) == 0.0
    run.run_until(lambda: bridge.status().last_sent == 0, 1.0, "clamped to closed")
    assert bridge.submit(0.5) == MAX_WIDTH
    run.run_until(lambda: bridge.status().last_sent == 100, 1.0, "clamped to open")
    assert controller.requests()[-2:] == [move(0, params), move(100, params)]
    assert events.matching("warn", "clamped") and bridge.status().clamped_inputs == 2
    run.clock.advance(params.error_log_period)  # the throttling period is on the bridge's clock too
    bridge.submit(math.nan)
    assert events.matching("error", "non-finite")[1:] == [
        "gripper bridge: dropped non-finite gripper width nan (3 more like this in the last 5 s)"]


# ----------------------------------------------------------------------------- end to end
def test_worker_thread_and_status_json_on_the_real_clock(controller):
    """The worker and the default XML-RPC client together, on the real clock: outcomes only."""
    params = make_params(controller_url=controller.url)
    bridge = GripperBridge(params, MAX_WIDTH, report=Events())

    def wait_for_sent(percent: int) -> None:
        deadline = time.monotonic() + 10.0  # a guard against a hang, not a measurement
        while bridge.status().last_sent != percent:
            assert time.monotonic() < deadline, f"no move to {percent} %: {bridge.status()}"
            time.sleep(0.005)

    bridge.start()
    try:
        bridge.submit(0.02)
        wait_for_sent(25)
        time.sleep(0.05)  # not needed to pass: lets the worker go idle (no probes), so a lost wake-up shows
        bridge.submit(0.04)  # must wake the idle worker
        wait_for_sent(50)
    finally:
        bridge.stop()
    fields = json.loads(bridge.status().to_json())
    assert {"mode", "connected", "last_error", "last_sent", "calls", "failures"} <= set(fields)
    assert fields["mode"] == "position" and fields["connected"] is True and fields["calls"] == 4
    assert controller.requests() == activation(params) + [move(25, params), move(50, params)]
