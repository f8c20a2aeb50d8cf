#!/usr/bin/env python3
"""Export a trained policy to ONNX with its normalisation folded in. Logic lives in fr5_rl.training.export_onnx."""
import sys

from fr5_rl.training.export_onnx import main

if __name__ == "__main__":
    sys.exit(main())
