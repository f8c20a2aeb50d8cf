#!/usr/bin/env python3
"""Clearing the table through the whole rehearsal (issue #54): scenes of several objects, each
object picked, carried to the next drop slot and set down, in real time, through the simulated
RealSense, the detector's selection, tf, the policy node and the vendor driver and gripper as
the simulator emulates them.

One launch: ``sim_policy.launch model:=M vision:=true driver:=fairino scene:=clear scenes:=N``
(:mod:`fr5_rl.scene_episodes`: config/clearing.yaml's pick area, rule and drop slots; one record
per object). Measured: objects placed out of objects (a neighbour knocked over fails the pick
that did it and counts as an object not placed), failures by cause, by kind and by the object's
place in its scene; the time per object: the episode itself (the first command to the verdict)
and the cycle (one verdict to the next: the start move, the camera's look at the next object
and the pick and place).

    python tools/bench/clearing.py --model models/place --scenes 10 --seed 6000000

Target (issue #54): >= 90 % of the objects placed over 10 scenes of 3-5 objects. Writes
bench/results/clearing.json (``--results``).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any, Dict, List, Optional

import numpy as np

from benchlib import AT_LEAST, REPO, RESULTS_DIR, machine_info, update_summary, verdict, write_result
from roslaunch_run import run_launch

TARGET_PLACED = 0.90


def summarise(records: List[Dict[str, Any]], control_dt: float) -> Dict[str, Any]:
    """Objects placed, failures by cause, by kind and by order in the scene, and the times."""
    placed = sum(bool(record["success"]) for record in records)
    causes: Dict[str, int] = {}
    by_kind: Dict[str, Dict[str, int]] = {}
    by_order: Dict[str, Dict[str, int]] = {}
    for record in records:
        for table, key in ((by_kind, record.get("object", "?")), (by_order, str(record.get("object_in_scene", "?")))):
            row = table.setdefault(key, {"placed": 0, "objects": 0})
            row["objects"] += 1
            row["placed"] += bool(record["success"])
        if not record["success"]:
            causes[record["failure"]] = causes.get(record["failure"], 0) + 1
    episode_s = [record["steps"] * control_dt for record in records if record["success"]]
    # The cycle: from the verdict before to this one, in simulated time (which runs with the wall
    # clock in real time), within a scene; a record with no episode (knocked over) has none.
    cycle_s = [after["sim_time"] - before["sim_time"] for before, after in zip(records, records[1:])
               if after.get("scene") == before.get("scene") and after["success"] and "sim_time" in after
               and "sim_time" in before]
    scenes = sorted({record.get("scene") for record in records})

    def stats(values: List[float]) -> Dict[str, Optional[float]]:
        return {"mean_s": round(float(np.mean(values)), 2) if values else None,
                "p50_s": round(float(np.percentile(values, 50)), 2) if values else None,
                "p90_s": round(float(np.percentile(values, 90)), 2) if values else None}

    return {"objects": len(records), "placed": placed, "placed_share": round(placed / len(records), 4) if records else None,
            "scenes": len(scenes), "failures": causes, "by_kind": by_kind, "by_order_in_scene": by_order,
            "knocked_neighbours": sum(len(record.get("knocked", [])) for record in records),
            "episode_time_placed": stats(episode_s), "cycle_time_placed": stats(cycle_s)}


def main(argv: Optional[List[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--model", default="models/place")
    parser.add_argument("--scenes", type=int, default=10)
    parser.add_argument("--seed", type=int, default=6_000_000, help="the run's seed: scene k and episode k follow from it")
    parser.add_argument("--backend", choices=("onnx", "torch"), default="onnx")
    parser.add_argument("--port", type=int, default=11490)
    parser.add_argument("--results", type=Path, default=RESULTS_DIR)
    args = parser.parse_args(argv)

    from fr5_rl.clearing import ClearingSettings
    from fr5_rl.deploy.bundle import deployment_overrides, read_meta
    from fr5_rl.episode import Episode
    from fr5_rl.scene_episodes import scene_sizes

    model_dir = Path(args.model) if Path(args.model).is_absolute() else REPO / args.model
    meta = read_meta(model_dir)
    episode = Episode.build(meta["task"], None, deployment_overrides(meta))
    sizes = scene_sizes(episode, ClearingSettings.from_yaml(), args.seed, args.scenes)
    control_dt = episode.control_dt
    episode.close()
    objects = sum(sizes)
    print(f"clearing {args.scenes} scenes of {', '.join(map(str, sizes))} objects ({objects}) with {args.model}",
          flush=True)
    arguments = {"rviz": False, "model": args.model, "vision": True, "driver": "fairino", "scene": "clear",
                 "scenes": args.scenes, "seed": args.seed, "backend": args.backend,
                 "controller_port": args.port + 8700}
    run = run_launch(arguments, port=args.port, episodes=objects, node_name="bench_clearing")
    summary = summarise(run.records, control_dt)
    share = summary["placed_share"]
    verdicts = {"placed": verdict(share, TARGET_PLACED, AT_LEAST, "", "objects placed")}
    print(f"placed {summary['placed']}/{summary['objects']} objects over {summary['scenes']} scenes; failures "
          f"{summary['failures'] or '-'}; knocked neighbours {summary['knocked_neighbours']}; episode "
          f"{summary['episode_time_placed']['mean_s']} s, cycle {summary['cycle_time_placed']['mean_s']} s per "
          f"object placed (mean); {run.wall_s:.0f} s", flush=True)
    for kind, row in summary["by_kind"].items():
        print(f"  {kind}: {row['placed']}/{row['objects']}")
    print(verdicts["placed"]["text"])
    path = args.results / "clearing.json"
    write_result(path, {"bench": "clearing", "model": args.model, "seed": args.seed, "scene_sizes": sizes,
                        "backend": args.backend, "wall_s": round(run.wall_s, 1), "timed_out": run.timed_out,
                        **summary, "records": run.records}, verdicts, machine=machine_info())
    update_summary(args.results, "clearing", path)
    print(f"wrote {path}")
    return 0 if run.episodes == objects else 1


if __name__ == "__main__":
    sys.exit(main())
