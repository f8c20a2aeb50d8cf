#!/usr/bin/env python3
"""Print a URDF tree for a launch file (ghost prefix, or the part below a link). Logic lives in fr5_rl.ros.robot_description."""
import sys

from fr5_rl.ros.robot_description import main

if __name__ == "__main__":
    sys.exit(main())
