#!/usr/bin/env python3
"""`rosrun fr5_rl compare_run.py --help`. The command line lives in fr5_rl.cli.compare_run."""
import sys

from fr5_rl.cli.compare_run import main

if __name__ == "__main__":
    sys.exit(main())
