#!/usr/bin/env python3
"""ROS node: PyBullet stand-in for the FR5 driver, gripper and camera. Logic lives in fr5_rl.ros.sim_node."""
import sys

from fr5_rl.ros.sim_node import main

if __name__ == "__main__":
    sys.exit(main())
