"""``rosrun fr5_rl export_onnx.py MODEL_DIR``: write MODEL_DIR/model.onnx.

The graph takes the raw observation and returns the deterministic action, normalisation
folded in. ``--check N`` compares it with the SB3 model on N observations from real rollouts.
"""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import List, Optional

from ..config import ConfigError, robot_names
from ..deploy.bundle import ModelFilesError, arm_of
from ..help_text import HelpFormatter, plain
from . import fail, script_args

def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="export_onnx.py", description=plain(__doc__.split("\n\n")[0]),
                                     epilog=plain(__doc__.split("\n\n", 1)[1]), formatter_class=HelpFormatter)
    parser.add_argument("model_dir", type=Path, help="model directory (meta.json, model.zip, vecnormalize.pkl)")
    parser.add_argument("--check", type=int, default=1000, help="parity check on N rollout observations (0: skip)")
    parser.add_argument("--robot", choices=robot_names(), default=None,
                        help="refuse a model trained for another arm (default: any)")
    return parser


def main(argv: Optional[List[str]] = None) -> int:
    args = build_parser().parse_args(script_args(argv))
    from ..training.onnx_export import PARITY_TOLERANCE, export, parity

    try:
        if args.robot is not None:
            arm_of(args.model_dir, args.robot)
        path = export(args.model_dir)
        print(f"wrote {path}")
        if args.check:
            worst = parity(args.model_dir, args.check)
            print(f"parity over {args.check} rollout observations: max |delta action| = {worst:.2e}")
            if worst > PARITY_TOLERANCE:
                return fail("export_onnx.py", f"ONNX and SB3 disagree by {worst:.2e} > {PARITY_TOLERANCE:g}")
    except (ConfigError, ModelFilesError) as error:
        return fail("export_onnx.py", error)
    return 0
