#!/usr/bin/env python3
"""ROS node: runs a trained policy on /joint_states + /target_pose at 50 Hz. Logic lives in fr5_rl.ros.policy_node."""
import sys

from fr5_rl.ros.policy_node import main

if __name__ == "__main__":
    sys.exit(main())
