#!/usr/bin/env python3
"""`rosrun fr5_rl calibrate_camera.py --help`: hand-eye calibration of the fixed camera. Logic in fr5_rl.ros.calibrate_camera."""
import sys

from fr5_rl.ros.calibrate_camera import main

if __name__ == "__main__":
    sys.exit(main())
