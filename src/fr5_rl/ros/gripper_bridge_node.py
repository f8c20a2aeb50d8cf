"""Gripper bridge node: the policy's gripper width (std_msgs/Float64, m) to the FR5 controller's XML-RPC server.

This module is I/O only. Each width on ``~command_topic`` is handed to
:class:`~fr5_rl.drivers.gripper_bridge.GripperBridge`, which keeps only the newest one and
makes every XML-RPC call (:mod:`fr5_rl.drivers.fr5_xmlrpc`) on its own worker thread:
``ActGripper`` + ``MoveGripper`` (``~mode`` position) or the manufacturer's ``SetToolDO``
open/close pairs (``~mode`` binary), rate-limited, with retries and exponential backoff while
the controller is unreachable or returns error codes. The subscriber callback never waits on
the network.

In position mode the bridge reads the fingers back (``GetGripperCurPosition``, SDK >= 2.1.2) at
``~readback_rate``, ignores the controller's transient 0 right after a move (``~zero_debounce``),
holds a move while the newest reading is older than ``~readback_max_age`` (a stream of moves
would otherwise keep every read inside that transient) and publishes ``~joint_states_topic``
(sensor_msgs/JointState: the two finger joints of config/gripper.yaml, each at width / 2, no
velocities, stamped at the read). ``~fault_topic``
(std_msgs/Bool, latched) is true while the gripper cannot act on a width: the controller is
unreachable (or not yet heard) or reports a gripper fault, or (position mode) the gripper is
not yet activated or its activation has not settled (``~activation_settle``). The policy node
holds on it, so a policy does not start before the fingers can follow it.

The bridge's state goes to ``~status`` (std_msgs/String, JSON: mode, connected, last_error,
last_sent, calls, failures, ...) and ``/diagnostics`` at ``~status_rate``. Errors go to the
log, throttled per kind (``~error_log_period``). Parameters: ``config/gripper_bridge.yaml``.
"""
from __future__ import annotations

import rospy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Float64, String

from ..config import ConfigError, load_robot_spec
from ..drivers.gripper_bridge import BridgeStatus, GripperBridge, GripperReading
from ..drivers.gripper_bridge_params import GripperBridgeParams
from .params import exit_if_help_asked, node_parameters
from .lifetime import init_node


def log_to_rosout(level: str, text: str) -> None:
    """The bridge's reports in the ROS log (already throttled by the bridge)."""
    {"error": rospy.logerr, "warn": rospy.logwarn}.get(level, rospy.loginfo)(text)


class GripperBridgeNode:
    """Subscriber, status publishers and one :class:`GripperBridge` with its worker thread."""

    def __init__(self) -> None:
        self.params = params = node_parameters(GripperBridgeParams, "gripper_bridge")
        spec = load_robot_spec()
        max_width, self.finger_names = spec.max_opening_width, list(spec.finger_joint_names)
        self.joint_states_pub = rospy.Publisher(params.joint_states_topic, JointState, queue_size=10)
        self.fault_pub = rospy.Publisher(params.fault_topic, Bool, queue_size=1, latch=True)
        self.fault_pub.publish(Bool(data=True))  # the gripper cannot act yet: not heard from, not activated
        self.bridge = GripperBridge(params, max_width, report=log_to_rosout, on_reading=self.publish_fingers,
                                    on_fault=self.publish_fault)
        self.status_pub = rospy.Publisher("~status", String, queue_size=1, latch=True)
        self.diagnostics_pub = rospy.Publisher("/diagnostics", DiagnosticArray, queue_size=1)
        # queue_size > 1: binary mode's hysteresis should see every width (submit is cheap).
        rospy.Subscriber(params.command_topic, Float64, self.on_command, queue_size=10, tcp_nodelay=True)
        rospy.loginfo(f"gripper_bridge: {params.mode} mode, controller {params.controller_url}, "
                      f"commands from {rospy.resolve_name(params.command_topic)}, max opening {max_width:g} m")
        self.bridge.start()
        rospy.on_shutdown(self.bridge.stop)
        self.status_timer = rospy.Timer(rospy.Duration(1.0 / params.status_rate), self.publish_status)

    def on_command(self, message: Float64) -> None:
        self.bridge.submit(message.data)  # stores the width and returns: no XML-RPC here

    def publish_fingers(self, reading: GripperReading) -> None:
        """Each accepted read-back as the finger joints (the bridge's worker thread, right after the reply)."""
        message = JointState(name=self.finger_names, position=[0.5 * reading.width] * len(self.finger_names))
        # The read's time on the ROS clock: the request went out a round trip (ms) before now.
        message.header.stamp = rospy.Time.now()
        self.joint_states_pub.publish(message)

    def publish_fault(self, fault: bool) -> None:
        """The fault state, each time it changes (latched: a late subscriber hears the current one)."""
        self.fault_pub.publish(Bool(data=fault))
        if fault:
            rospy.logwarn(f"gripper_bridge: gripper fault on {rospy.resolve_name(self.params.fault_topic)} "
                          f"(~status: {self.bridge.status().last_error or 'gripper fault reported'})")
        else:
            rospy.loginfo(f"gripper_bridge: the gripper can act: fault cleared on {rospy.resolve_name(self.params.fault_topic)}")

    def publish_status(self, _event: rospy.timer.TimerEvent) -> None:
        status = self.bridge.status()
        self.status_pub.publish(String(data=status.to_json()))
        self.diagnostics_pub.publish(diagnostics_message(status, rospy.get_name()))


def diagnostics_message(status: BridgeStatus, node_name: str) -> DiagnosticArray:
    """``/diagnostics``: OK while connected without error, WARN on controller errors, ERROR when lost."""
    entry = DiagnosticStatus(name=f"{node_name.lstrip('/')}: FR5 gripper", hardware_id=status.controller_url)
    if not status.connected:
        entry.level, entry.message = DiagnosticStatus.ERROR, "controller not reachable"
    elif status.last_error:
        entry.level, entry.message = DiagnosticStatus.WARN, status.last_error
    else:
        entry.level, entry.message = DiagnosticStatus.OK, "connected"
    entry.values = [KeyValue(key=key, value=str(value)) for key, value in
                    (("mode", status.mode), ("last_sent", status.last_sent), ("desired", status.desired),
                     ("calls", status.calls), ("failures", status.failures), ("retry_in_s", status.retry_in),
                     ("measured_width_m", status.measured_width), ("gripper_fault", status.gripper_fault))]
    message = DiagnosticArray(status=[entry])
    message.header.stamp = rospy.Time.now()
    return message


def main() -> int:
    exit_if_help_asked("gripper_bridge_node.py", __doc__.split("\n\n")[0], "gripper_bridge")
    init_node("fr5_gripper_bridge")
    try:
        GripperBridgeNode()
    except ConfigError as error:
        rospy.logfatal(f"gripper_bridge: {error}")
        return 1
    rospy.spin()
    return 0
