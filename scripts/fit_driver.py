#!/usr/bin/env python3
"""`rosrun fr5_rl fit_driver.py --help`. The command line lives in fr5_rl.cli.fit_driver."""
import sys

from fr5_rl.cli.fit_driver import main

if __name__ == "__main__":
    sys.exit(main())
