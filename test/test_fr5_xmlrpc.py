"""The FR5 controller's XML-RPC client (fr5_rl.drivers.fr5_xmlrpc) against the loopback stand-in:
the vendor's argument order, error codes, faults, timeouts and refused connections."""
from __future__ import annotations


import pytest

from fr5_controller_standin import CLOSE_PAIR, OPEN_PAIR
from fr5_rl.drivers.fr5_xmlrpc import (
    GRIPPER_ACTIVATE, NON_BLOCKING, PANEL_CLOSE, PANEL_OPEN, Call, ControllerClient, ControllerRefused,
    ControllerUnreachable, TimeoutTransport, act_gripper, cur_position_of, error_code_of, get_gripper_activate_status,
    get_gripper_cur_position, get_gripper_motion_done, motion_done_fault, move_gripper, move_gripper_10, set_tool_do,
)

# ----------------------------------------------------------------------------- the XML-RPC client
def test_vendor_calls_keep_the_sdks_argument_order():
    """FR5_FACTS: ActGripper(index, act), MoveGripper(index, pos%, vel%, force%, max_time_ms, block),
    SetToolDO(id, status, smooth, block), and the rviz panel's pairs."""
    assert act_gripper(1, GRIPPER_ACTIVATE) == Call("ActGripper", (1, 1))
    assert move_gripper(2, 40, 30, 20, 15000, NON_BLOCKING) == Call("MoveGripper", (2, 40, 30, 20, 15000, 1))
    assert set_tool_do(1, 0, 0, 0) == Call("SetToolDO", (1, 0, 0, 0))
    assert get_gripper_motion_done() == Call("GetGripperMotionDone", ())
    assert [(c.method, c.args) for c in PANEL_CLOSE] == CLOSE_PAIR
    assert [(c.method, c.args) for c in PANEL_OPEN] == OPEN_PAIR
    assert str(move_gripper(1, 50, 50, 50, 30000, 1)) == "MoveGripper(1, 50, 50, 50, 30000, 1)"
    assert motion_done_fault((3, 1)) == 3 and motion_done_fault(()) is None and motion_done_fault(("x",)) is None


def test_newer_sdk_calls_and_the_position_read_back():
    """FR5_FACTS: the 10-argument MoveGripper (type, rotNum, rotVel, rotTorque last) and
    GetGripperCurPosition() -> (error, fault, position%)."""
    assert move_gripper_10(1, 40, 30, 20, 15000, NON_BLOCKING, 0, 0, 0, 0) == Call(
        "MoveGripper", (1, 40, 30, 20, 15000, 1, 0, 0, 0, 0))
    assert get_gripper_cur_position() == Call("GetGripperCurPosition", ())
    assert get_gripper_activate_status() == Call("GetGripperActivateStatus", ())
    assert cur_position_of((0, 55)) == (0, 55.0) and cur_position_of((3, 12.5)) == (3, 12.5)
    for odd in ((), (0,), (0, "x"), (True, 5), (0, 5, 1)):
        with pytest.raises(ControllerRefused, match="GetGripperCurPosition"):
            cur_position_of(odd)


def test_error_code_of_accepts_an_int_or_a_list_led_by_the_code():
    assert error_code_of(0) == (0, ())
    assert error_code_of([0, 3, 1]) == (0, (3, 1))
    assert error_code_of((14,)) == (14, ())
    for odd in ("0", [], ["x"], True, None, 0.0):
        with pytest.raises(ControllerRefused):
            error_code_of(odd)


def test_client_reports_codes_faults_timeouts_and_refused_connections(controller):
    assert TimeoutTransport(0.2).make_connection("127.0.0.1:1").timeout == 0.2  # no connection made yet
    client = ControllerClient(controller.url, timeout=0.2)
    assert client.call(Call("MoveGripper", (1, 50, 50, 50, 30000, 1))) == ()
    assert client.call(Call("GetGripperMotionDone", ())) == (0, 1)
    controller.error_codes["ActGripper"] = 7
    with pytest.raises(ControllerRefused, match="error code 7") as refused:
        client.call(Call("ActGripper", (1, 1)))
    assert refused.value.code == 7
    with pytest.raises(ControllerRefused, match="fault"):
        client.call(Call("NoSuchCall", ()))
    # The stand-in answers 0 after 3 s: only the 0.2 s socket timeout can turn this into an error.
    controller.delay = 3.0
    with pytest.raises(ControllerUnreachable, match="no reply within 0.2 s") as hung:
        client.call(Call("MoveGripper", (1, 50, 50, 50, 30000, 1)))
    assert hung.value.timed_out
    controller.delay = 0.0
    assert client.call(Call("SetToolDO", (0, 1, 0, 0))) == ()  # a fresh connection after the timeout
    controller.stop()
    with pytest.raises(ControllerUnreachable) as refused_connection:
        client.call(Call("ActGripper", (1, 1)))
    assert not refused_connection.value.timed_out  # refused at once, not mistaken for a hang
