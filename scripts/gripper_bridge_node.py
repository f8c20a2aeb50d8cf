#!/usr/bin/env python3
"""ROS node: FR5 gripper commands to the controller's XML-RPC server. Logic lives in fr5_rl.ros.gripper_bridge_node."""
import sys

from fr5_rl.ros.gripper_bridge_node import main

if __name__ == "__main__":
    sys.exit(main())
