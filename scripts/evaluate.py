#!/usr/bin/env python3
"""Evaluate a trained FR5 policy: rosrun fr5_rl evaluate.py --help. Logic lives in fr5_rl.training.evaluate."""
import sys

from fr5_rl.training.evaluate import main

if __name__ == "__main__":
    sys.exit(main())
