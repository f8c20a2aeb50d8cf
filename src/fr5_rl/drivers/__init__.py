"""Drivers for the FR5's hardware that is not on ROS: the controller's XML-RPC client and the
gripper bridge's logic. No ROS here: ``fr5_rl.ros.gripper_bridge_node`` wraps it."""
