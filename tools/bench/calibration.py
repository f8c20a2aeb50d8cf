#!/usr/bin/env python3
"""The camera's hand-eye calibration rehearsed: hidden mount errors recovered, and reach through
vision before and after.

For each ``--offsets`` entry (dx dy dz droll dpitch dyaw, m and rad, camera_link frame) it runs
``sim_policy.launch vision:=true calibration:=true sim_camera_offset:=...`` on its own ROS
master and ``calibrate_camera.py --out FILE`` against it, and compares the recovered mount with
the true one (config/static_transforms.yaml's composed with the offset): translation error (mm)
and rotation error (deg). Then, for the ``--reach`` offsets, ``--episodes`` reach episodes through
vision with the offset, first with the configured transforms, then with the calibrated file
(``static_transforms:=FILE``), on the same seeds.

Writes ``calibration.json`` (and the calibrated files, ``calibrated_<k>.yaml``) in ``--results``.

    python tools/bench/calibration.py --results docs/bench/calibration --episodes 20 --seed 1100000
"""
from __future__ import annotations

import argparse
import math
import os
import re
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any, Dict, List, Optional

from benchlib import machine_info, relative_path, write_result
from fr5_rl.perception.hand_eye import offset_transform, rpy_from_rotation, transform_error
from fr5_rl.training.evaluation import wilson_interval
from fr5_rl.transforms import load_static_transforms, transform_in
from roslaunch_run import _default_sigint, _stop, launch_command, master_uri, run_launch

# Up to 3 cm and 3 degrees, mixed signs, each translation and rotation together.
OFFSETS = [
    "0.010 -0.010 0.005 0.010 -0.015 0.020",
    "-0.015 0.012 -0.010 -0.020 0.025 -0.015",
    "0.020 -0.015 0.010 0.020 -0.030 0.035",
    "-0.012 -0.020 0.015 0.030 0.020 -0.030",
    "0.020 0.015 -0.015 -0.030 0.030 0.025",
]


def calibrate(offset: str, out: Path, port: int, timeout: float) -> Dict[str, Any]:
    """One calibration against a launch with the hidden ``offset``: the tool's printed lines,
    exit status and wall time."""
    command = launch_command({"vision": True, "calibration": True, "rviz": False, "sim_camera_offset": offset}, port)
    env = dict(os.environ, ROS_MASTER_URI=master_uri(port))
    launch = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env,
                              start_new_session=True, preexec_fn=_default_sigint)
    output: List[str] = []
    reader = threading.Thread(target=lambda: output.extend(launch.stdout), daemon=True)
    reader.start()
    try:
        # Asked through `rostopic` rather than by joining as a node: a process joins one master only.
        deadline = time.time() + 120.0
        while "/camera/color/image_raw" not in subprocess.run(["rostopic", "list"], env=env, capture_output=True,
                                                               text=True).stdout.split():
            if time.time() > deadline or launch.poll() is not None:
                raise RuntimeError("no camera topic from the launch:\n" + "".join(output[-20:]))
            time.sleep(1.0)
        started = time.time()
        tool = subprocess.run(["rosrun", "fr5_rl", "calibrate_camera.py", "--out", str(out), "--force"], env=env,
                              capture_output=True, text=True, timeout=timeout)
        wall = time.time() - started
    finally:
        _stop(launch)
        reader.join(timeout=5.0)
    return {"returncode": tool.returncode, "lines": (tool.stdout + tool.stderr).splitlines(), "wall_s": round(wall, 1)}


def compare(offset: str, out: Path) -> Dict[str, Any]:
    """The recovered mount against the true one."""
    values = [float(v) for v in offset.split()]
    configured = transform_in(load_static_transforms(), "base_link", "camera_link")
    true = configured @ offset_transform(values)
    recovered = transform_in(load_static_transforms(out), "base_link", "camera_link")
    error_m, error_rad = transform_error(recovered, true)
    before_m, before_rad = transform_error(configured, true)
    return {"offset": values,
            "offset_size": {"translation_mm": round(math.hypot(*values[:3]) * 1e3, 1),
                            "rotation_deg": round(math.degrees(transform_error(offset_transform(values),
                                                                             offset_transform([0] * 6))[1]), 2)},
            "true": {"xyz": [round(v, 5) for v in true[:3, 3]], "rpy": [round(v, 5) for v in rpy_from_rotation(true[:3, :3])]},
            "recovered": {"xyz": [round(v, 5) for v in recovered[:3, 3]],
                          "rpy": [round(v, 5) for v in rpy_from_rotation(recovered[:3, :3])]},
            "error": {"translation_mm": round(error_m * 1e3, 2), "rotation_deg": round(math.degrees(error_rad), 3)},
            "configured_error": {"translation_mm": round(before_m * 1e3, 1),
                                 "rotation_deg": round(math.degrees(before_rad), 2)}}


def reach(offset: str, transforms: Optional[Path], episodes: int, seed: int, port: int, timeout: float
          ) -> Dict[str, Any]:
    """Reach through vision with the hidden ``offset`` and the given transforms file (None: the
    configured). An episode starts with the policy's first command; with a wrong mount the
    detector may never publish a target (the table plane it computes is tilted), so the run is
    stopped after ``timeout`` s and the episodes that never started count as failures."""
    arguments: Dict[str, Any] = {"rviz": False, "model": "models/reach", "task": "reach", "episodes": episodes,
                                 "seed": seed, "vision": True, "sim_camera_offset": offset}
    if transforms is not None:
        arguments["static_transforms"] = str(transforms.resolve())
    run = run_launch(arguments, port=port, episodes=episodes, timeout=timeout)
    causes: Dict[str, int] = {}
    for cause in run.failures:
        causes[cause] = causes.get(cause, 0) + 1
    if run.episodes < episodes:
        causes["not started (no target from the detector)"] = episodes - run.episodes
    holds = [line.strip() for line in run.output if "holding:" in line]
    return {"transforms": "configured" if transforms is None else relative_path(transforms),
            "successes": run.successes, "episodes": episodes, "completed": run.episodes,
            "success_rate_95ci": [round(b, 3) for b in wilson_interval(run.successes, episodes)],
            "failures": causes, "seeds": [seed, seed + episodes - 1], "wall_s": round(run.wall_s, 1),
            "timed_out": run.timed_out, "hold_messages": len(holds), "last_hold": holds[-1][-200:] if holds else ""}


def main(argv: Optional[List[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--offsets", nargs="+", default=OFFSETS, help="hidden mount offsets, each 'dx dy dz droll dpitch dyaw'")
    parser.add_argument("--reach", nargs="*", type=int, default=[len(OFFSETS) - 1],
                        help="indices of the offsets to run reach through vision for, before and after (default: the last, largest)")
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--seed", type=int, default=1_100_000)
    parser.add_argument("--port", type=int, default=11480)
    parser.add_argument("--results", type=Path, required=True)
    parser.add_argument("--timeout", type=float, default=400.0, help="s one calibration may take")
    parser.add_argument("--reach-timeout", type=float, default=420.0,
                        help="s a reach run may take (episodes not started by then count as failures)")
    args = parser.parse_args(argv)
    args.results.mkdir(parents=True, exist_ok=True)
    rows: List[Dict[str, Any]] = []
    for index, offset in enumerate(args.offsets):
        out = args.results / f"calibrated_{index}.yaml"
        run = calibrate(offset, out, args.port + index, args.timeout)
        row: Dict[str, Any] = {"index": index, "offset_arg": offset, "returncode": run["returncode"],
                               "wall_s": run["wall_s"],
                               "report": [line for line in run["lines"] if re.match(r"(residual|base_link|cup centre|dropped|pose \d)", line)]}
        if run["returncode"] == 0:
            row.update(compare(offset, out))
            row["file"] = relative_path(out)
            print(f"offset {offset}: error {row['error']['translation_mm']} mm, {row['error']['rotation_deg']} deg "
                  f"(configured: {row['configured_error']}) in {run['wall_s']} s", flush=True)
        else:
            print(f"offset {offset}: calibrate_camera.py exited {run['returncode']}:\n" + "\n".join(run["lines"][-10:]),
                  flush=True)
        rows.append(row)
    reaches = []
    for index in args.reach:
        offset, out = args.offsets[index], args.results / f"calibrated_{index}.yaml"
        for transforms in (None, out):
            if transforms is not None and not out.is_file():
                continue
            result = {"offset_index": index, "offset_arg": offset,
                      **reach(offset, transforms, args.episodes, args.seed, args.port + 50,
                              args.reach_timeout)}
            reaches.append(result)
            print(f"reach through vision, offset {offset}, {result['transforms']}: "
                  f"{result['successes']}/{result['episodes']} {result['failures'] or ''}", flush=True)
    path = write_result(args.results / "calibration.json",
                        {"bench": "calibration", "machine": machine_info(), "calibrations": rows,
                         "reach_through_vision": reaches,
                         "targets": {"translation_mm": 5.0, "rotation_deg": 0.5, "reach_after": 0.9,
                                     "reach_before_below": 0.5}})
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
