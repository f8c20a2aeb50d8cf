"""``rosrun fr5_rl make_models.py --robot fr10``: make one arm's whole model set.

Reach, grasp and pick-and-place (config/recipes/model_set.yaml), each learnt with DAgger from the
scripted expert in the deployed world of the arm's own cell, shipped to models/<arm>/<stage>/
with its ONNX export, evaluated on held-out placements (plain and perturbed) and described by a
card. Run it again after a kill: what was made is kept and the rest continues.

examples:
  rosrun fr5_rl make_models.py --robot fr10
  rosrun fr5_rl make_models.py --robot fr3 --stages reach grasp
  rosrun fr5_rl make_models.py --robot fr10 --remake place   # after changing the place stage
  rosrun fr5_rl make_models.py --robot fr3 --evaluate-again place   # after changing the simulator
  make models ROBOT=fr16
"""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import List, Optional

from ..config import ConfigError, robot_names
from ..deploy.bundle import ModelFilesError
from ..help_text import HelpFormatter, plain
from . import fail, script_args


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="make_models.py", description=plain(__doc__.split("\n\n")[0]),
                                     epilog=plain(__doc__.split("\n\n", 1)[1]), formatter_class=HelpFormatter)
    parser.add_argument("--robot", choices=robot_names(), required=True, help="the arm (config/robots/)")
    parser.add_argument("--recipe", default=None, help="the recipe (default: config/recipes/model_set.yaml)")
    parser.add_argument("--stages", nargs="+", default=None, metavar="NAME", help="only these stages (default: all)")
    parser.add_argument("--remake", nargs="+", default=None, metavar="NAME",
                        help="make these stages again from nothing (after changing their recipe)")
    parser.add_argument("--evaluate-again", nargs="+", default=None, metavar="NAME",
                        help="evaluate these made stages again, their models as they are (after a change to the "
                             "simulator), and write their cards again")
    parser.add_argument("--models-dir", type=Path, default=None, help="where the models go (default: models/<arm>)")
    parser.add_argument("--run-root", type=Path, default=None,
                        help="the training runs and progress.json (default: runs/models_<arm>)")
    return parser


def main(argv: Optional[List[str]] = None) -> int:
    args = build_parser().parse_args(script_args(argv))
    from ..training.model_set import ModelSet, load_recipe

    try:
        recipe = load_recipe(args.recipe) if args.recipe else None
        result = ModelSet(args.robot, recipe, args.models_dir, args.run_root, args.stages, args.remake,
                          args.recipe, args.evaluate_again).run()
    except (ConfigError, ModelFilesError) as error:
        return fail("make_models.py", error)
    print(f"{args.robot}: model set made in {result['wall_time_s'] / 60:.1f} min (its stages'; this machine has spent "
          f"{result['machine_time_s'] / 60:.1f} min on it, stages made again included)")
    return 0
