"""The simulator's emulation of the FR5 controller's XML-RPC gripper methods
(fr5_rl.sim.controller_emulator), alone, over real XML-RPC on 127.0.0.1: the vendor's argument
order and units, both MoveGripper forms, the refusal before activation, the transient 0 after a
move, percent <-> width, motion done and the rviz panel's SetToolDO pairs.

Time is the emulator's injected clock, advanced only by the test.
"""
from __future__ import annotations

import subprocess
import sys
import xmlrpc.client
from typing import Iterator, List

import pytest

from fr5_rl.config import ConfigError, load_robot_spec, typed
from fr5_rl.sim.controller_emulator import (
    ERR_BAD_VALUE, ERR_NOT_ACTIVATED, FAULT_NO_SUCH_METHOD, FAULT_WRONG_ARITY, ControllerEmulator,
    ControllerEmulatorSettings,
)

MAX_WIDTH = load_robot_spec().max_opening_width  # 0.08 m
TRANSIENT = 0.1  # s: the field report's "reads 0 for a moment"


class Clock:
    """The emulator's injected clock (s): stands still until the test advances it."""

    def __init__(self) -> None:
        self.now = 50.0

    def __call__(self) -> float:
        return self.now

    def advance(self, seconds: float) -> None:
        self.now = round(self.now + seconds, 9)


def settings(forms: List[int], invert: bool = False, transient: float = TRANSIENT) -> ControllerEmulatorSettings:
    return ControllerEmulatorSettings(gripper_index=1, move_gripper_args=forms, invert_percent=invert,
                                      position_zero_transient=transient)


@pytest.fixture
def emulate() -> Iterator:
    """Factory: a started emulator on a free port, its clock, and an XML-RPC proxy to it; all stopped after."""
    started: List[ControllerEmulator] = []

    def make(forms: List[int], invert: bool = False, transient: float = TRANSIENT):
        clock = Clock()
        emulator = ControllerEmulator(settings(forms, invert, transient), 0, clock)
        emulator.start()
        started.append(emulator)
        return emulator, clock, xmlrpc.client.ServerProxy(emulator.url, allow_none=True)

    yield make
    for emulator in started:
        emulator.stop()


def activate(rpc: xmlrpc.client.ServerProxy) -> None:
    assert rpc.ActGripper(1, 0) == 0 and rpc.ActGripper(1, 1) == 0  # the vendor's example: reset, then activate


def test_settings_are_checked():
    good = dict(gripper_index=1, move_gripper_args=[6, 10], invert_percent=False, position_zero_transient=0.1)
    assert typed(ControllerEmulatorSettings, good, "test").move_gripper_args == [6, 10]
    for key, value in (("move_gripper_args", [7]), ("move_gripper_args", []), ("position_zero_transient", -0.1)):
        with pytest.raises(ConfigError, match=key):
            typed(ControllerEmulatorSettings, {**good, key: value}, "test")


def test_port_zero_picks_a_free_port_and_stop_makes_it_unreachable(emulate):
    emulator, _, rpc = emulate([6])
    assert emulator.port > 0 and emulator.url == f"http://127.0.0.1:{emulator.port}"
    assert rpc.GetGripperActivateStatus() == [0, 0, 0]
    emulator.stop()
    with pytest.raises(OSError):
        xmlrpc.client.ServerProxy(emulator.url).GetGripperActivateStatus()
    port = emulator.port
    emulator.start()  # back on the same port
    assert emulator.port == port and rpc.GetGripperActivateStatus() == [0, 0, 0]


def test_a_move_before_activation_is_refused(emulate):
    emulator, clock, rpc = emulate([6])
    assert rpc.MoveGripper(1, 50, 50, 50, 30000, 1) == ERR_NOT_ACTIVATED
    assert emulator.commanded_width() is None  # nothing moved
    activate(rpc)
    assert emulator.is_activated() and rpc.GetGripperActivateStatus() == [0, 0, 1]
    assert emulator.newest_command() is None
    clock.advance(1.5)
    assert rpc.MoveGripper(1, 50, 50, 50, 30000, 1) == 0
    assert emulator.commanded_width() == pytest.approx(0.04)
    # When it arrived, on the simulator's clock: a late simulator applies it from then on.
    assert emulator.newest_command() == (pytest.approx(clock.now), pytest.approx(0.04))
    assert rpc.ActGripper(1, 0) == 0  # a reset deactivates
    assert rpc.MoveGripper(1, 20, 50, 50, 30000, 1) == ERR_NOT_ACTIVATED
    assert emulator.commanded_width() == pytest.approx(0.04)
    assert rpc.ActGripper(2, 1) == ERR_BAD_VALUE and rpc.ActGripper(1, 2) == ERR_BAD_VALUE  # no gripper 2; act 0/1
    assert emulator.requests()[:2] == [("MoveGripper", (1, 50, 50, 50, 30000, 1)), ("ActGripper", (1, 0))]


@pytest.mark.parametrize("forms", [[6], [10], [6, 10]], ids=["6_only", "10_only", "both"])
def test_move_gripper_forms(emulate, forms):
    emulator, _, rpc = emulate(forms)
    activate(rpc)
    for count, args in ((6, (1, 25, 50, 50, 30000, 1)), (10, (1, 75, 50, 50, 30000, 1, 0, 0, 0, 0))):
        if count in forms:
            assert rpc.MoveGripper(*args) == 0
            assert emulator.commanded_width() == pytest.approx(args[1] / 100 * MAX_WIDTH)
        else:  # the wrong form is an XML-RPC fault, before the method runs
            with pytest.raises(xmlrpc.client.Fault) as fault:
                rpc.MoveGripper(*args)
            assert fault.value.faultCode == FAULT_WRONG_ARITY and f"got {count}" in fault.value.faultString
    with pytest.raises(xmlrpc.client.Fault) as fault:
        rpc.MoveGripper(1, 50, 50)
    assert fault.value.faultCode == FAULT_WRONG_ARITY
    with pytest.raises(xmlrpc.client.Fault) as fault:
        rpc.NoSuchCall()
    assert fault.value.faultCode == FAULT_NO_SUCH_METHOD


def test_move_gripper_values_are_checked(emulate):
    emulator, _, rpc = emulate([6, 10])
    activate(rpc)
    for args in ((1, 101, 50, 50, 30000, 1), (1, 50, -1, 50, 30000, 1), (1, 50, 50, 150, 30000, 1),
                 (1, 50, 50, 50, 30001, 1), (1, 50, 50, 50, 30000, 2), (3, 50, 50, 50, 30000, 1),
                 (1, "50", 50, 50, 30000, 1), (1, 50, 50, 50, 30000, 1, 1, 0, 0, 0)):  # type 1: rotary
        assert rpc.MoveGripper(*args) == ERR_BAD_VALUE, args
    assert emulator.commanded_width() is None
    assert rpc.MoveGripper(1, 37.5, 50, 50, 30000, 0) == 0  # a newer SDK sends the position as a double
    assert emulator.commanded_width() == pytest.approx(0.03)


@pytest.mark.parametrize("invert", [False, True], ids=["0%_closed", "0%_open"])
def test_percent_and_width_follow_the_bridges_convention(emulate, invert):
    emulator, clock, rpc = emulate([6], invert=invert)
    activate(rpc)
    assert rpc.MoveGripper(1, 25, 50, 50, 30000, 1) == 0
    assert emulator.commanded_width() == pytest.approx(0.06 if invert else 0.02)
    clock.advance(TRANSIENT)
    emulator.set_measured_width(0.02, moving=False)
    assert rpc.GetGripperCurPosition() == [0, 0, 75 if invert else 25]
    emulator.set_measured_width(MAX_WIDTH, moving=False)
    assert rpc.GetGripperCurPosition() == [0, 0, 0 if invert else 100]


def test_position_reads_zero_for_a_moment_after_a_move(emulate):
    emulator, clock, rpc = emulate([6])
    activate(rpc)
    emulator.set_measured_width(0.04, moving=False)
    assert rpc.GetGripperCurPosition() == [0, 0, 50]  # no move yet: no transient
    assert rpc.MoveGripper(1, 60, 50, 50, 30000, 1) == 0
    emulator.set_measured_width(0.041, moving=True)
    readings = []
    for _ in range(6):
        readings.append(rpc.GetGripperCurPosition()[2])
        clock.advance(0.03)
    assert readings == [0, 0, 0, 0, 51, 51]  # 0 for TRANSIENT s after the move, then the fingers


def test_the_transient_can_be_turned_off(emulate):
    emulator, _, rpc = emulate([6], transient=0.0)
    activate(rpc)
    emulator.set_measured_width(0.04, moving=False)
    assert rpc.MoveGripper(1, 60, 50, 50, 30000, 1) == 0
    assert rpc.GetGripperCurPosition() == [0, 0, 50]


def test_motion_done_needs_the_simulator_to_have_seen_the_command(emulate):
    emulator, _, rpc = emulate([6])
    activate(rpc)
    assert rpc.GetGripperMotionDone() == [0, 0, 1]  # nothing commanded: done
    assert rpc.MoveGripper(1, 10, 50, 50, 30000, 1) == 0
    emulator.set_measured_width(0.04, moving=False)  # a report about the old command: still moving
    assert rpc.GetGripperMotionDone() == [0, 0, 0]
    assert emulator.commanded_width() == pytest.approx(0.008)
    emulator.set_measured_width(0.03, moving=True)
    assert rpc.GetGripperMotionDone() == [0, 0, 0]
    emulator.set_measured_width(0.02, moving=False)  # stopped on an object, short of the target
    assert rpc.GetGripperMotionDone() == [0, 0, 1]
    emulator.set_gripper_fault(7)
    assert rpc.GetGripperMotionDone()[:2] == [0, 7] and rpc.GetGripperCurPosition()[:2] == [0, 7]
    assert rpc.GetGripperActivateStatus() == [0, 7, 1]


def test_set_tool_do_pairs_open_and_close(emulate):
    emulator, _, rpc = emulate([6])
    assert emulator.commanded_width() is None
    # The manufacturer's rviz panel: close = DO0 on, DO1 off; open = DO0 off, DO1 on. No activation needed.
    close, open_ = ((0, 1, 0, 0), (1, 0, 0, 0)), ((0, 0, 0, 0), (1, 1, 0, 0))
    widths = []
    for pair in (close, open_, close, close, open_):
        for args in pair:
            assert rpc.SetToolDO(*args) == 0
            widths.append(emulator.commanded_width())
    # From (0, 0), DO0 on already reads closed; after that the first half of a pair gives (0, 0) or
    # (1, 1), which commands nothing, and the second half completes the new state.
    assert widths == [0.0, 0.0, 0.0, MAX_WIDTH, MAX_WIDTH, 0.0, 0.0, 0.0, 0.0, MAX_WIDTH]
    for args in ((2, 1, 0, 0), (0, 2, 0, 0), (0, 1, 3, 0), (0, 1, 0, 5)):
        assert rpc.SetToolDO(*args) == ERR_BAD_VALUE, args
    with pytest.raises(xmlrpc.client.Fault):
        rpc.SetToolDO(0, 1)


def test_the_emulator_imports_neither_pybullet_nor_the_drivers():
    code = ("import sys, fr5_rl.sim.controller_emulator; "
            "print(sorted(m for m in sys.modules if m.startswith(('pybullet', 'fr5_rl.drivers', 'rospy'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert out.stdout.strip() == "[]"
