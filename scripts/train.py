#!/usr/bin/env python3
"""`rosrun fr5_rl train.py --help`. The command line lives in fr5_rl.cli.train."""
import sys

from fr5_rl.cli.train import main

if __name__ == "__main__":
    sys.exit(main())
