#!/usr/bin/env python3
"""`rosrun fr5_rl imitate.py --help`. The command line lives in fr5_rl.cli.imitate."""
import sys

from fr5_rl.cli.imitate import main

if __name__ == "__main__":
    sys.exit(main())
