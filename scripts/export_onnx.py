#!/usr/bin/env python3
"""`rosrun fr5_rl export_onnx.py --help`. The command line lives in fr5_rl.cli.export_onnx."""
import sys

from fr5_rl.cli.export_onnx import main

if __name__ == "__main__":
    sys.exit(main())
