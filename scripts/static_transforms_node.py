#!/usr/bin/env python3
"""ROS node: publishes config/static_transforms.yaml on /tf_static in one call. Logic lives in fr5_rl.ros.static_transforms."""
import sys

from fr5_rl.ros.static_transforms import main

if __name__ == "__main__":
    sys.exit(main())
