"""The gripper bridge (fr5_rl.drivers.gripper_bridge) driving the simulator's emulation of the FR5
controller (fr5_rl.sim.controller_emulator) end to end over real XML-RPC on 127.0.0.1: widths in
-> the emulator's commanded width; the emulator's measured width -> the bridge's read-back; the
debounce of the controller's transient 0 after a move; the fault state.

The bridge and the emulator share one injected clock, advanced only by the test
(test_gripper_bridge.Driven runs each due step on the test's thread): no assertion depends on
how fast the machine is.
"""
from __future__ import annotations

from typing import Iterator, List

import pytest

from fr5_rl.drivers.fr5_xmlrpc import ControllerClient
from fr5_rl.drivers.gripper_bridge import GripperReading
from fr5_rl.sim.controller_emulator import ControllerEmulator, ControllerEmulatorSettings
from test_gripper_bridge import MAX_WIDTH, WITHIN_A_TICK, Driven, FakeClock, make_params

TRANSIENT = 0.1  # s the emulated controller reads 0 after a move (the field report)


class Cell:
    """An emulated controller and a bridge on one fake clock; what the bridge reports is collected."""

    def __init__(self, forms: List[int], **overrides) -> None:
        self.clock = FakeClock()
        self.emulator = ControllerEmulator(
            ControllerEmulatorSettings(gripper_index=1, move_gripper_args=forms, invert_percent=False,
                                       position_zero_transient=TRANSIENT), 0, self.clock)
        self.emulator.start()
        self.readings: List[GripperReading] = []
        self.faults: List[bool] = []
        params = make_params(controller_url=self.emulator.url, **{"readback_rate": 20.0, **overrides})
        self.run = Driven(params, ControllerClient(params.controller_url, params.call_timeout), self.clock,
                          on_reading=self.readings.append, on_fault=self.faults.append)
        self.bridge = self.run.bridge

    def simulate(self, seconds: float, finger_speed: float) -> None:
        """The simulator's side: the fingers move toward the commanded width at ``finger_speed`` (m/s),
        reported to the emulator each 1 ms tick, while the bridge runs."""
        width = None
        for _ in range(int(round(seconds / 0.001))):
            target = self.emulator.commanded_width()
            width = self.emulator.measured if width is None else width
            if target is not None and width is not None:
                step = max(-finger_speed * 0.001, min(finger_speed * 0.001, target - width))
                width = width + step
                self.emulator.set_measured_width(width, moving=abs(target - width) > 1e-9)
            self.run.run_for(0.001)


@pytest.fixture
def cell() -> Iterator:
    made: List[Cell] = []

    def make(forms: List[int], **overrides) -> Cell:
        made.append(Cell(forms, **overrides))
        return made[-1]

    yield make
    for each in made:
        each.emulator.stop()


@pytest.mark.parametrize("args", [6, 10])
def test_widths_in_commanded_width_out_and_the_measured_width_back(cell, args):
    c = cell([6, 10], move_gripper_args=args)
    c.emulator.set_measured_width(MAX_WIDTH, moving=False)  # the fingers start open
    c.bridge.submit(0.02)
    c.run.run_until(lambda: c.emulator.commanded_width() is not None, 1.0, "the emulator to be commanded")
    assert c.emulator.commanded_width() == pytest.approx(0.02)
    moves = [(m, a) for m, a in c.emulator.requests() if m in ("ActGripper", "MoveGripper")]
    assert moves[:2] == [("ActGripper", (1, 0)), ("ActGripper", (1, 1))]  # reset, then activate
    assert moves[2] == ("MoveGripper", (1, 25, 50, 50, 30000, 1) + (0, 0, 0, 0)[:args - 6])
    c.simulate(1.0, finger_speed=0.16)  # 0.08 -> 0.02 m in 0.375 s
    assert c.readings[-1].width == pytest.approx(0.02) and c.readings[-1].fault == 0
    widths = [r.width for r in c.readings]
    assert widths == sorted(widths, reverse=True) and widths[0] > 0.05  # followed the fingers closing
    assert c.bridge.status().measured_width == pytest.approx(0.02)


def test_the_wrong_move_gripper_form_is_refused_and_never_commands(cell):
    c = cell([10], move_gripper_args=6)  # a newer controller, an old setting
    c.bridge.submit(0.04)
    c.run.run_until(lambda: c.bridge.status().failures >= 2, 1.0, "two refused MoveGripper")
    status = c.bridge.status()
    assert "fault -502" in status.last_error and status.connected and status.last_sent is None
    assert c.emulator.commanded_width() is None


def test_a_transient_zero_is_not_published_a_persistent_one_is(cell):
    c = cell([6], zero_debounce=0.3)
    c.emulator.set_measured_width(0.04, moving=False)
    c.bridge.submit(0.04)
    c.run.run_until(lambda: c.emulator.commanded_width() is not None, 1.0, "the first move")
    c.run.run_for(0.5)
    assert c.readings and all(r.width == pytest.approx(0.04) for r in c.readings)
    ignored = c.bridge.status().ignored_zero_readings
    assert ignored >= 1  # the first reads after the move were the controller's transient 0

    # A move that the fingers do not need to follow far: the emulator reads 0 for TRANSIENT s.
    count = len(c.readings)
    c.bridge.submit(0.06)
    c.run.run_until(lambda: c.emulator.commanded_width() == pytest.approx(0.06), 1.0, "the second move")
    c.run.run_for(0.5)
    new = c.readings[count:]
    assert new and all(r.width > 0.0 for r in new), [r.width for r in new]
    assert c.bridge.status().ignored_zero_readings > ignored

    # Closed on nothing: 0 % persists past the debounce window and is published.
    c.emulator.set_measured_width(0.0, moving=False)
    c.bridge.submit(0.0)
    c.run.run_until(lambda: c.emulator.commanded_width() == 0.0, 1.0, "the close")
    moved_at = c.clock.now
    c.run.run_until(lambda: c.readings[-1].width == 0.0, 1.0, "the persistent 0 to be published")
    zeros = [r for r in c.readings if r.width == 0.0]
    assert zeros[0].stamp - moved_at >= 0.3 - 0.002  # not before the window closed (one tick of slack)


def test_without_the_debounce_the_transient_zero_would_be_published(cell):
    """The debounce is what keeps the transient 0 out: with it off, the same move publishes 0."""
    c = cell([6], zero_debounce=0.0)
    c.emulator.set_measured_width(0.04, moving=False)
    c.bridge.submit(0.04)
    c.run.run_until(lambda: c.emulator.commanded_width() is not None, 1.0, "the first move")
    c.run.run_for(0.5)
    assert any(r.width == 0.0 for r in c.readings) and c.bridge.status().ignored_zero_readings == 0


def test_no_width_reaches_the_fingers_while_the_fault_holds(cell):
    """The vendor's timings (reset, 1 s, activate, 2 s): the fault clears when the first
    MoveGripper may go out, so a policy that holds on the fault never commands fingers that
    cannot follow. The read-back runs from the activation on and shows them where they stand."""
    c = cell([6], reset_settle=1.0, activation_settle=2.0)
    c.emulator.set_measured_width(MAX_WIDTH, moving=False)
    c.bridge.submit(0.0)  # a close asked for at once
    took = c.run.run_until(lambda: c.faults == [False], 5.0, "the fault to clear")
    assert took == pytest.approx(3.0, abs=WITHIN_A_TICK)
    moves = c.run.recorder.times("MoveGripper")
    assert moves and moves[0] >= c.clock.now - WITHIN_A_TICK  # the first move goes out as it clears
    assert c.readings and all(r.width == pytest.approx(MAX_WIDTH) for r in c.readings)  # open until then


def test_the_fault_state_follows_gripper_faults_and_the_link(cell):
    c = cell([6], retry_initial=0.05, retry_max=0.1)
    c.emulator.set_measured_width(0.04, moving=False)
    assert c.bridge.status().fault  # nothing heard yet
    c.run.run_until(lambda: c.faults == [False], 1.0, "the activation to clear the fault")
    assert c.bridge.status().activated
    c.emulator.set_gripper_fault(5)
    c.run.run_until(lambda: c.faults[-1:] == [True], 1.0, "the gripper fault")
    assert c.bridge.status().gripper_fault == 5 and c.bridge.status().connected
    c.emulator.set_gripper_fault(0)
    c.run.run_until(lambda: c.faults[-1:] == [False], 1.0, "the gripper fault to clear")
    c.emulator.stop()
    c.run.run_until(lambda: c.faults[-1:] == [True], 1.0, "the lost controller")
    assert not c.bridge.status().connected
    c.emulator.start()
    c.run.run_until(lambda: c.faults[-1:] == [False], 1.0, "the controller back")
    assert c.faults == [False, True, False, True, False]  # one report per change, no repeats


def test_binary_mode_drives_the_emulator_with_the_panel_pairs_and_reads_nothing(cell):
    c = cell([6], mode="binary")
    c.bridge.submit(0.01)
    c.run.run_until(lambda: c.emulator.commanded_width() == 0.0, 1.0, "close")
    c.bridge.submit(0.07)
    c.run.run_until(lambda: c.emulator.commanded_width() == pytest.approx(MAX_WIDTH), 1.0, "open")
    c.run.run_for(0.3)
    methods = {m for m, _ in c.emulator.requests()}
    assert methods == {"SetToolDO"} and c.readings == []
