"""The gripper bridge (fr5_rl.runtime.gripper_bridge) against a loopback stand-in for the FR5
controller's XML-RPC server: what it sends in each mode, how often, and what it does when the
controller returns error codes, hangs, or goes away and comes back.

:class:`StandInController` is also used by the rostest (test/rostest/test_gripper_bridge_node.py).
"""
from __future__ import annotations

import dataclasses
import math
import socketserver
import threading
import time
from typing import Callable, Dict, List, Optional, Tuple
from xmlrpc.server import SimpleXMLRPCServer

import pytest

from fr5_rl.config import ConfigError, load_robot_spec, load_typed, typed
from fr5_rl.runtime.gripper_bridge import (
    Backoff, Call, ControllerClient, ControllerRefused, ControllerUnreachable, GripperBridge, GripperBridgeParams,
    ThrottledReport, binary_state, error_code_of, needs_move, width_to_percent,
)

MAX_WIDTH = load_robot_spec().max_opening_width  # 0.08 m
CLOSE_PAIR = [("SetToolDO", (0, 1, 0, 0)), ("SetToolDO", (1, 0, 0, 0))]
OPEN_PAIR = [("SetToolDO", (0, 0, 0, 0)), ("SetToolDO", (1, 1, 0, 0))]


# ----------------------------------------------------------------------------- the stand-in
class _ThreadingXMLRPCServer(socketserver.ThreadingMixIn, SimpleXMLRPCServer):
    # Threads: a delayed (hanging) request must not keep the next one from being answered.
    daemon_threads = True

    def handle_error(self, request, client_address) -> None:
        pass  # the bridge hung up on a delayed request: expected, not worth a traceback


class StandInController:
    """Loopback XML-RPC server playing the FR5 controller.

    Records every request as ``(monotonic time, method, args)``; replies 0 (or ``[0]`` with
    ``list_replies``), or the code set in ``error_codes[method]``; sleeps ``delay`` seconds before
    replying; ``stop()`` takes it off the network (listening socket closed) and ``start()``
    brings it back on the same port.
    """

    def __init__(self, port: int = 0) -> None:
        self.lock = threading.Lock()
        self.calls: List[Tuple[float, str, tuple]] = []
        self.error_codes: Dict[str, int] = {}
        self.delay = 0.0
        self.list_replies = False
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
        if method not in ("ActGripper", "MoveGripper", "SetToolDO", "GetGripperMotionDone"):
            raise ValueError(f'method "{method}" is not supported')  # becomes an XML-RPC Fault
        if method == "GetGripperMotionDone":
            return [code, 0, 1]  # [error, fault, status]: no fault, motion done
        return [code] if self.list_replies else code

    def requests(self, since: float = 0.0, probes: bool = False) -> List[Tuple[str, tuple]]:
        """(method, args) of the requests recorded from ``since`` on, without probes unless asked."""
        with self.lock:
            return [(m, a) for t, m, a in self.calls if t >= since and (probes or m != "GetGripperMotionDone")]

    def times(self, method: str, since: float = 0.0) -> List[float]:
        with self.lock:
            return [t for t, m, _ in self.calls if m == method and t >= since]


# ----------------------------------------------------------------------------- helpers
def make_params(**overrides) -> GripperBridgeParams:
    """config/gripper_bridge.yaml with fast test timings, then ``overrides``."""
    fast = dict(max_call_rate=50.0, call_timeout=0.2, retry_initial=0.05, retry_max=0.2, probe_period=0.0,
                activation_settle=0.0, error_log_period=0.0, status_rate=10.0)
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


def wait_until(predicate: Callable[[], bool], timeout: float = 3.0, what: str = "condition") -> float:
    """Poll ``predicate`` until true; returns the seconds it took, fails the test on timeout."""
    start = time.monotonic()
    while not predicate():
        if time.monotonic() - start > timeout:
            pytest.fail(f"timed out after {timeout} s waiting for {what}")
        time.sleep(0.005)
    return time.monotonic() - start


def move(percent: int, params: GripperBridgeParams) -> Tuple[str, tuple]:
    return ("MoveGripper", (params.gripper_index, percent, params.velocity_percent, params.force_percent,
                            params.max_time_ms, 1))


@pytest.fixture
def controller():
    stand_in = StandInController()
    yield stand_in
    stand_in.stop()


@pytest.fixture
def run_bridge():
    """Factory: a started bridge on the stand-in; stopped at the end of the test."""
    bridges = []

    def start(controller: StandInController, **overrides) -> Tuple[GripperBridge, Events, GripperBridgeParams]:
        params = make_params(controller_url=controller.url, **overrides)
        events = Events()
        bridge = GripperBridge(params, MAX_WIDTH, report=events)
        bridge.start()
        bridges.append(bridge)
        return bridge, events, params

    yield start
    for bridge in bridges:
        bridge.stop()


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
    now = [0.0]
    out = []
    report = ThrottledReport(lambda level, text: out.append((level, text)), 5.0, clock=lambda: now[0])
    for _ in range(4):
        report("error", "lost", "controller lost")
    report("warn", "clamped", "clamped")  # another kind is not held back
    assert out == [("error", "controller lost"), ("warn", "clamped")]
    now[0] = 5.1
    report("error", "lost", "controller lost")
    assert out[-1] == ("error", "controller lost (3 more like this in the last 5 s)")
    report.forget("lost")
    report("error", "lost", "again")
    assert out[-1] == ("error", "again")


def test_error_code_of_accepts_an_int_or_a_list_led_by_the_code():
    assert error_code_of(0) == (0, ())
    assert error_code_of([0, 3, 1]) == (0, (3, 1))
    assert error_code_of((14,)) == (14, ())
    for odd in ("0", [], ["x"], True, None, 0.0):
        with pytest.raises(ControllerRefused):
            error_code_of(odd)


# ----------------------------------------------------------------------------- the client
def test_client_reports_codes_faults_timeouts_and_refused_connections(controller):
    client = ControllerClient(controller.url, timeout=0.2)
    assert client.call(Call("MoveGripper", (1, 50, 50, 50, 30000, 1))) == ()
    assert client.call(Call("GetGripperMotionDone", ())) == (0, 1)
    controller.error_codes["ActGripper"] = 7
    with pytest.raises(ControllerRefused, match="error code 7") as refused:
        client.call(Call("ActGripper", (1, 1)))
    assert refused.value.code == 7
    with pytest.raises(ControllerRefused, match="fault"):
        client.call(Call("NoSuchCall", ()))
    controller.delay = 1.0
    start = time.monotonic()
    with pytest.raises(ControllerUnreachable) as hung:
        client.call(Call("MoveGripper", (1, 50, 50, 50, 30000, 1)))
    assert hung.value.timed_out and time.monotonic() - start < 0.6  # the 0.2 s timeout, not the 1 s delay
    controller.delay = 0.0
    assert client.call(Call("SetToolDO", (0, 1, 0, 0))) == ()  # a fresh connection after the timeout
    controller.stop()
    start = time.monotonic()
    with pytest.raises(ControllerUnreachable) as refused_connection:
        client.call(Call("ActGripper", (1, 1)))
    assert not refused_connection.value.timed_out and time.monotonic() - start < 0.2


# ----------------------------------------------------------------------------- position mode
def test_position_mode_activates_once_then_moves_past_the_deadband(controller, run_bridge):
    bridge, events, params = run_bridge(controller, deadband_percent=2)
    bridge.submit(0.04)
    wait_until(lambda: len(controller.requests()) >= 2, what="ActGripper + MoveGripper")
    assert controller.requests() == [("ActGripper", (params.gripper_index, 1)), move(50, params)]

    def settle_then_requests():
        time.sleep(5 / params.max_call_rate)  # several call slots: anything due would have been sent
        return controller.requests()[2:]

    bridge.submit(0.0408)  # 51 %: inside the deadband
    assert settle_then_requests() == []
    bridge.submit(0.0416)  # 52 %: 2 % from the last sent
    wait_until(lambda: len(controller.requests()) >= 3, what="MoveGripper 52")
    bridge.submit(0.0792)  # 99 %
    wait_until(lambda: len(controller.requests()) >= 4, what="MoveGripper 99")
    bridge.submit(0.08)  # 100 %: 1 % only, but an end stop
    wait_until(lambda: len(controller.requests()) >= 5, what="MoveGripper 100")
    bridge.submit(0.0796)  # rounds to 100 %: nothing new
    assert settle_then_requests() == [move(52, params), move(99, params), move(100, params)]
    status = bridge.status()
    assert status.connected and status.activated and status.last_sent == 100 and status.calls == 5
    assert status.failures == 0 and status.last_error == "" and events.matching("error", "") == []


def test_burst_is_rate_limited_and_the_newest_width_wins(controller, run_bridge):
    bridge, _, params = run_bridge(controller, max_call_rate=20.0, deadband_percent=1)
    wait_until(lambda: controller.requests() != [], what="ActGripper")
    start = time.monotonic()
    widths = [0.08 * ((i * 37) % 100) / 100 for i in range(99)] + [0.03]  # jumping around, last 0.03 m
    worst_submit = 0.0
    for width in widths:
        before = time.monotonic()
        bridge.submit(width)
        worst_submit = max(worst_submit, time.monotonic() - before)
        time.sleep(0.002)
    burst = time.monotonic() - start
    wait_until(lambda: bridge.status().last_sent == 38, what="the last width (38 %) to be sent")
    time.sleep(3 / params.max_call_rate)
    moves = controller.times("MoveGripper")
    allowed = math.floor((moves[-1] - start) * params.max_call_rate) + 1
    assert 1 <= len(moves) <= allowed, f"{len(moves)} MoveGripper calls for a {burst:.2f} s burst at {params.max_call_rate} Hz"
    assert len(moves) < 20  # 100 commands coalesced
    gaps = [b - a for a, b in zip(moves, moves[1:])]
    # Measured on arrival at the stand-in, which adds scheduling jitter; unlimited calls would
    # arrive milliseconds apart.
    assert all(gap >= 0.5 / params.max_call_rate for gap in gaps), gaps
    assert controller.requests()[-1] == move(38, params)
    assert worst_submit < 0.05


@pytest.mark.parametrize("list_replies", [False, True], ids=["int_reply", "list_reply"])
def test_error_code_is_reported_and_retried_with_growing_backoff(controller, run_bridge, list_replies):
    controller.list_replies = list_replies
    controller.error_codes["MoveGripper"] = 14
    bridge, events, params = run_bridge(controller, retry_initial=0.05, retry_max=0.4)
    bridge.submit(0.02)
    wait_until(lambda: bridge.status().failures >= 4, what="4 refused MoveGripper attempts")
    status = bridge.status()
    assert status.connected and "error code 14" in status.last_error and status.failures >= 4
    assert status.last_sent is None and status.retry_in > 0
    assert events.matching("error", "error code 14")
    attempts = controller.times("MoveGripper")
    gaps = [b - a for a, b in zip(attempts, attempts[1:])]
    # 0.05, 0.1, 0.2 s: lower bounds only (a loaded machine adds delay; the exact schedule is
    # checked on a fake clock below). Without growth the 2nd and 3rd gaps would be ~0.05 s.
    assert gaps[0] >= 0.045 and gaps[1] >= 0.09 and gaps[2] >= 0.18, gaps
    del controller.error_codes["MoveGripper"]
    wait_until(lambda: bridge.status().last_sent == 25, timeout=2.0, what="success once the code is 0")
    assert bridge.status().last_error == "" and controller.requests()[-1] == move(25, params)
    assert controller.requests().count(("ActGripper", (params.gripper_index, 1))) == 1  # the link never dropped


def test_backoff_schedule_on_a_fake_clock():
    """The exact retry times, cap included, with an injected clock and the caller's thread."""
    now = [100.0]

    class ScriptedController:
        def __init__(self):
            self.made: List[Tuple[float, str]] = []
            self.code = 0

        def call(self, call: Call):
            self.made.append((now[0], call.method))
            if call.method == "MoveGripper" and self.code:
                raise ControllerRefused(f"{call} returned error code {self.code}", self.code)
            return ()

    client = ScriptedController()
    params = make_params(retry_initial=0.1, retry_max=0.5, max_call_rate=10.0, activation_settle=1.0)
    bridge = GripperBridge(params, MAX_WIDTH, report=Events(), client=client, clock=lambda: now[0])
    assert bridge.poll() == "activate"
    bridge.submit(0.04)
    now[0] += 0.99
    assert bridge.poll() is None  # activation_settle (1 s) not over
    now[0] += 0.01
    client.code = 3
    assert bridge.poll() == "move"
    retries = []
    while len(retries) < 5:
        now[0] = round(now[0] + 0.01, 6)
        if bridge.poll() == "move":
            retries.append(now[0])
    attempts = [t for t, m in client.made if m == "MoveGripper"]
    assert [round(b - a, 6) for a, b in zip(attempts, attempts[1:])] == [0.1, 0.2, 0.4, 0.5, 0.5]
    client.code = 0
    now[0] += 0.5
    assert bridge.poll() == "move" and bridge.status().last_sent == 50 and bridge.status().last_error == ""
    now[0] += 0.1
    bridge.submit(0.0)
    assert bridge.poll() == "move"  # backoff reset by the success: only the 10 Hz limit applies
    assert bridge.status().last_sent == 0


def test_timeout_reports_an_error_and_never_blocks_submit(controller, run_bridge):
    bridge, events, params = run_bridge(controller, call_timeout=0.2, retry_initial=0.05, retry_max=0.2)
    bridge.submit(0.04)
    wait_until(lambda: bridge.status().last_sent == 50, what="first move")
    controller.delay = 1.5  # the controller hangs
    hang_start = time.monotonic()
    bridge.submit(0.06)
    wait_until(lambda: len(controller.times("MoveGripper", hang_start)) >= 1, what="the hanging request")
    durations = []
    for i in range(20):  # while the worker waits on the hanging controller
        before = time.monotonic()
        bridge.submit(0.02 + 0.001 * i)
        durations.append(time.monotonic() - before)
    assert max(durations) < 0.05, f"submit() blocked {max(durations) * 1000:.1f} ms behind the hanging request"
    wait_until(lambda: events.matching("error", "timed out"), timeout=1.0, what="the timeout error")
    detect = time.monotonic() - controller.times("MoveGripper", hang_start)[0]  # from the request's arrival
    assert bridge.status().connected is False and "no reply within 0.2 s" in bridge.status().last_error
    assert detect < 0.6
    controller.delay = 0.0
    back = time.monotonic()
    recover = wait_until(lambda: bridge.status().last_sent == 49, timeout=2.0, what="recovery")  # newest: 0.039 m
    after = controller.requests(since=back)
    assert after[-2:] == [("ActGripper", (params.gripper_index, 1)), move(49, params)], after
    assert events.matching("info", "answers again")
    print(f"\ntimeout: error {detect:.3f} s after the request began hanging (call_timeout {params.call_timeout} s), "
          f"recovered {recover:.3f} s after the controller answered again")


@pytest.mark.parametrize("mode", ["position", "binary"])
def test_controller_gone_and_back_resends_the_newest_state(controller, run_bridge, mode):
    bridge, events, params = run_bridge(controller, mode=mode, probe_period=0.1, retry_initial=0.05, retry_max=0.2)
    bridge.submit(0.07)
    first = [("ActGripper", (params.gripper_index, 1)), move(88, params)] if mode == "position" else OPEN_PAIR
    wait_until(lambda: controller.requests() == first, what="the first state")
    controller.stop()  # mid-run, while idle: the liveness probe must notice
    gone = time.monotonic()
    detect = wait_until(lambda: not bridge.status().connected, timeout=1.0, what="the loss to be noticed")
    bridge.submit(0.01)  # a new state while the controller is away
    time.sleep(0.5)
    status = bridge.status()
    assert status.failures >= 3 and "unreachable" in events.matching("error", "unreachable")[0]
    assert status.last_sent is None and status.desired == (12 if mode == "position" else "closed")
    controller.start()  # same port
    back = time.monotonic()
    recover = wait_until(lambda: bridge.status().last_sent is not None, timeout=1.0, what="recovery")
    resent = controller.requests(since=back)
    expected = [("ActGripper", (params.gripper_index, 1)), move(12, params)] if mode == "position" else CLOSE_PAIR
    assert resent == expected
    assert bridge.status().connected and bridge.status().last_error == ""
    assert detect < 0.1 + params.call_timeout + 0.2 and recover < params.retry_max + 0.3
    print(f"\n{mode}: loss noticed after {detect:.3f} s (probe every {params.probe_period} s), "
          f"recovered {recover:.3f} s after the controller came back (backoff cap {params.retry_max} s); "
          f"down {back - gone:.2f} s")


def test_reactivation_can_be_turned_off(controller, run_bridge):
    bridge, _, params = run_bridge(controller, reactivate_after_reconnect=False, probe_period=0.05)
    bridge.submit(0.04)
    wait_until(lambda: bridge.status().last_sent == 50, what="first move")
    controller.stop()
    wait_until(lambda: not bridge.status().connected, what="the loss")
    controller.start()
    back = time.monotonic()
    wait_until(lambda: bridge.status().last_sent == 50, what="the resend")
    assert controller.requests(since=back) == [move(50, params)]


# ----------------------------------------------------------------------------- binary mode
def test_binary_mode_sends_the_pairs_in_order_without_chatter(controller, run_bridge):
    bridge, _, params = run_bridge(controller, mode="binary", binary_threshold=0.04, binary_hysteresis=0.005)

    def quiet_after(widths: List[float]) -> List[Tuple[str, tuple]]:
        count = len(controller.requests())
        for width in widths:
            bridge.submit(width)
            time.sleep(1.5 / params.max_call_rate)  # each width gets its own call slot
        return controller.requests()[count:]

    bridge.submit(0.07)
    wait_until(lambda: len(controller.requests()) == 2, what="open pair")
    assert quiet_after([0.038, 0.042, 0.0355, 0.0445, 0.036]) == []  # noise inside 0.035 … 0.045 m
    bridge.submit(0.03)
    wait_until(lambda: len(controller.requests()) == 4, what="close pair")
    assert quiet_after([0.041, 0.044, 0.036, 0.0449]) == []
    bridge.submit(0.05)
    wait_until(lambda: len(controller.requests()) == 6, what="open pair")
    # Close then, within one call slot, a width inside the band: the band keeps "closed".
    bridge.submit(0.01)
    bridge.submit(0.04)
    wait_until(lambda: len(controller.requests()) == 8, what="close pair")
    time.sleep(3 / params.max_call_rate)
    assert controller.requests() == OPEN_PAIR + CLOSE_PAIR + OPEN_PAIR + CLOSE_PAIR
    assert bridge.status().last_sent == "closed" and bridge.status().calls == 8
    assert "ActGripper" not in [m for m, _ in controller.requests(probes=True)]


def test_binary_pair_half_done_is_resent_whole(controller, run_bridge):
    controller.error_codes["SetToolDO"] = 9
    bridge, events, _ = run_bridge(controller, mode="binary")
    bridge.submit(0.0)
    wait_until(lambda: len(controller.requests()) >= 2, what="two refused attempts")
    assert set(controller.requests()) == {CLOSE_PAIR[0]}  # the second call never follows a failed first
    del controller.error_codes["SetToolDO"]
    wait_until(lambda: bridge.status().last_sent == "closed", what="the close pair")
    assert controller.requests()[-2:] == CLOSE_PAIR and events.matching("error", "error code 9")


# ----------------------------------------------------------------------------- bad inputs
def test_bad_widths_are_dropped_or_clamped(controller, run_bridge):
    bridge, events, params = run_bridge(controller, error_log_period=5.0)
    wait_until(lambda: bridge.status().activated, what="activation")
    for bad in (math.nan, math.inf, -math.inf, "abc"):
        assert bridge.submit(bad) is None
    time.sleep(5 / params.max_call_rate)
    assert controller.requests() == [("ActGripper", (params.gripper_index, 1))]  # nothing sent for them
    assert len(events.matching("error", "non-finite")) == 1  # throttled: one line for the four
    assert bridge.status().dropped_inputs == 4 and bridge.status().desired is None
    assert bridge.submit(-0.01) == 0.0
    wait_until(lambda: bridge.status().last_sent == 0, what="clamped to closed")
    assert bridge.submit(0.5) == MAX_WIDTH
    wait_until(lambda: bridge.status().last_sent == 100, what="clamped to open")
    assert controller.requests()[-2:] == [move(0, params), move(100, params)]
    assert events.matching("warn", "clamped") and bridge.status().clamped_inputs == 2


def test_status_is_json_with_the_documented_fields(controller, run_bridge):
    import json

    bridge, _, _ = run_bridge(controller)
    bridge.submit(0.02)
    wait_until(lambda: bridge.status().last_sent == 25, what="a move")
    fields = json.loads(bridge.status().to_json())
    assert {"mode", "connected", "last_error", "last_sent", "calls", "failures"} <= set(fields)
    assert fields["mode"] == "position" and fields["connected"] is True and fields["calls"] == 2
