#!/usr/bin/env python3
"""ROS node: the ghost robot of a dry run (rviz). Logic lives in fr5_rl.ros.ghost_robot."""
import sys

from fr5_rl.ros.ghost_robot import main

if __name__ == "__main__":
    sys.exit(main())
