#!/usr/bin/env python3
"""Train a policy on an FR5 task: rosrun fr5_rl train.py --help. Logic lives in fr5_rl.training.train."""
import sys

from fr5_rl.training.train import main

if __name__ == "__main__":
    sys.exit(main())
