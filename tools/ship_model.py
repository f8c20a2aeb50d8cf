"""Turn a training run into a shipped model directory.

    python tools/ship_model.py RUN_DIR/final models/reach [--run-dir RUN_DIR] [--episodes 200]

Copies model.zip, vecnormalize.pkl and meta.json (adding the run's training steps, wall time,
time to solve and machine), exports model.onnx with the parity check, evaluates on held-out
seeds into eval.json/eval.csv (``scripts/evaluate.py``, as a subprocess: eval.json is what that
command writes), and draws the learning curve into docs/.

Imports library modules only (``fr5_rl.deploy``, ``fr5_rl.training``), never ``fr5_rl.cli``.
"""
import argparse
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import List, Optional

from fr5_rl.deploy.bundle import META_FILE, MODEL_FILE, STATS_FILE, ModelFilesError, read_meta, write_json_atomic
from fr5_rl.training.evaluation import plot_learning_curve
from fr5_rl.training.onnx_export import PARITY_TOLERANCE, export, parity

REPO = Path(__file__).resolve().parents[1]
PARITY_OBSERVATIONS = 1000
# summary.json key -> meta.json key (what evaluate.py copies into eval.json)
FROM_SUMMARY = {"wall_time_s": "training_wall_time_s", "time_to_solve_s": "time_to_solve_s",
                "timesteps_to_solve": "timesteps_to_solve", "machine": "machine", "method": "training_method",
                "best_round": "training_best_round"}


def main(argv: Optional[List[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("source", type=Path)
    parser.add_argument("target", type=Path)
    parser.add_argument("--run-dir", type=Path, default=None, help="default: the source's parent")
    parser.add_argument("--episodes", type=int, default=200)
    args = parser.parse_args(argv)
    run_dir = args.run_dir or args.source.parent
    try:
        meta = read_meta(args.source)
    except ModelFilesError as error:
        return f"ship_model.py: {error}"
    summary = json.loads((run_dir / "summary.json").read_text())
    args.target.mkdir(parents=True, exist_ok=True)
    for name in (MODEL_FILE, STATS_FILE):
        shutil.copy2(args.source / name, args.target / name)
    meta.update({target: summary[key] for key, target in FROM_SUMMARY.items() if key in summary})
    meta["source_run"] = run_dir.name
    write_json_atomic(args.target / META_FILE, meta)

    try:
        print(f"wrote {export(args.target)}")
        worst = parity(args.target, PARITY_OBSERVATIONS)
    except ModelFilesError as error:
        return f"ship_model.py: {error}"
    print(f"parity over {PARITY_OBSERVATIONS} rollout observations: max |delta action| = {worst:.2e}")
    if worst > PARITY_TOLERANCE:
        return f"ship_model.py: ONNX and SB3 disagree by {worst:.2e} > {PARITY_TOLERANCE:g}"

    environment = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(REPO / "src"),
                                                                             os.environ.get("PYTHONPATH")])))
    evaluation = subprocess.run([sys.executable, str(REPO / "scripts" / "evaluate.py"), str(args.target),
                                 "--episodes", str(args.episodes), "--out", str(args.target / "eval.json"),
                                 "--force"], env=environment)
    if evaluation.returncode != 0:
        return "ship_model.py: evaluation failed"

    if (run_dir / "eval" / "evaluations.npz").is_file() or summary.get("method") == "dagger":
        out = plot_learning_curve(run_dir, REPO / "docs" / f"learning_curve_{args.target.name}.png")
        print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
