#!/usr/bin/env python3
"""`rosrun fr5_rl make_models.py --help`. The command line lives in fr5_rl.cli.make_models."""
import sys

from fr5_rl.cli.make_models import main

if __name__ == "__main__":
    sys.exit(main())
