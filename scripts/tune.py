#!/usr/bin/env python3
"""`rosrun fr5_rl tune.py --help`. The command line lives in fr5_rl.cli.tune."""
import sys

from fr5_rl.cli.tune import main

if __name__ == "__main__":
    sys.exit(main())
