"""Turn a training run into a shipped model directory.

    python tools/ship_model.py RUN_DIR/final models/reach [--run-dir RUN_DIR] [--episodes 200]

Copies model.zip, vecnormalize.pkl and meta.json (adding the run's training steps, wall time,
time to solve and machine), exports model.onnx with the parity check, evaluates on held-out
seeds into eval.json/eval.csv, and draws the learning curve into docs/.
"""
import argparse
import json
import shutil
import sys
from pathlib import Path

from fr5_rl.training import evaluate, export_onnx
from fr5_rl.training.artifacts import META_FILE, MODEL_FILE, STATS_FILE, read_meta, write_json_atomic

parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
parser.add_argument("source", type=Path)
parser.add_argument("target", type=Path)
parser.add_argument("--run-dir", type=Path, default=None, help="default: the source's parent")
parser.add_argument("--episodes", type=int, default=200)
args = parser.parse_args()
run_dir = args.run_dir or args.source.parent
meta = read_meta(args.source)
summary = json.loads((run_dir / "summary.json").read_text())
args.target.mkdir(parents=True, exist_ok=True)
for name in (MODEL_FILE, STATS_FILE):
    shutil.copy2(args.source / name, args.target / name)
# summary.json key -> meta.json key (what evaluate.py copies into eval.json)
FROM_SUMMARY = {"wall_time_s": "training_wall_time_s", "time_to_solve_s": "time_to_solve_s",
                "timesteps_to_solve": "timesteps_to_solve", "machine": "machine", "method": "training_method",
                "best_round": "training_best_round"}
meta.update({target: summary[key] for key, target in FROM_SUMMARY.items() if key in summary})
meta["source_run"] = run_dir.name
write_json_atomic(args.target / META_FILE, meta)
if export_onnx.main([str(args.target), "--check", "1000"]) != 0:
    sys.exit("ONNX export failed its parity check")
if evaluate.main([str(args.target), "--episodes", str(args.episodes)]) != 0:
    sys.exit("evaluation failed")
if (run_dir / "eval" / "evaluations.npz").is_file() or summary.get("method") == "dagger":
    evaluate.main(["--plot", str(run_dir), "--plot-out", f"docs/learning_curve_{meta['task']}.png"])
