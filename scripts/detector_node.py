#!/usr/bin/env python3
"""ROS node: the object's centre from an RGB-D camera, as /target_pose. Logic lives in fr5_rl.ros.detector_node."""
import sys

from fr5_rl.ros.detector_node import main

if __name__ == "__main__":
    sys.exit(main())
