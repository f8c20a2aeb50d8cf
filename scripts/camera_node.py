#!/usr/bin/env python3
"""ROS node: simulated RGB-D camera of the simulator's scene. Logic lives in fr5_rl.ros.camera_node."""
import sys

from fr5_rl.ros.camera_node import main

if __name__ == "__main__":
    sys.exit(main())
