#!/usr/bin/env python3
"""`rosrun fr5_rl evaluate.py --help`. The command line lives in fr5_rl.cli.evaluate."""
import sys

from fr5_rl.cli.evaluate import main

if __name__ == "__main__":
    sys.exit(main())
