"""``rosrun fr5_rl compare_run.py FILE.bag --out DIR``: how far is the simulator from the arm?

Replays the recorded commands in the simulator from the recorded start state, at the recorded
times, behind a driver profile (the vendor driver's by default, or --driver-profile), and writes
to DIR: ``report.json`` (tracking error RMS and max per joint, the delay by which the arm and the
simulation follow the commands, the share of commands at a limit) and per-joint pictures of the
recorded against the simulated position (``overview.png`` first: every joint's error at a glance).

Examples::

    roslaunch fr5_rl record.launch bag:=run1.bag          # beside real_policy.launch
    rosrun fr5_rl compare_run.py run1.bag --out gap_default
    rosrun fr5_rl fit_driver.py run1.bag --out fitted.yaml
    rosrun fr5_rl compare_run.py run1.bag --out gap_fitted --driver-profile fitted.yaml
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import List, Optional

from ..env_config import TASK_NAMES
from ..config import DEFAULT_ROBOT, ConfigError, load_robot_spec, robot_names
from ..deploy.bundle import write_json_atomic
from ..sim.driver_profile import load_driver_profile, profile_summary
from ..sim_to_real.compare import joint_table, plot_joints, run_report
from ..sim_to_real.fit import load_sim_to_real_settings
from ..sim_to_real.replay import replay_error
from ..sim_to_real.recording import RecordingError, read_recording
from . import fail, parser_from_doc, script_args


def build_parser() -> argparse.ArgumentParser:
    parser = parser_from_doc("compare_run.py", __doc__)
    parser.add_argument("bag", type=Path, help="a run recorded with record.launch")
    parser.add_argument("--out", type=Path, required=True, help="directory for report.json and the pictures")
    parser.add_argument("--driver-profile", default=None,
                        help="the profile to replay behind (a file, or a name in config/; default: "
                             "config/sim_to_real.yaml's base_profile, the vendor driver's)")
    parser.add_argument("--baseline-profile", default=None,
                        help="also replay behind this profile and draw its error beside (e.g. the default, "
                             "to see what a fitted profile gained)")
    parser.add_argument("--joint-states-topic", default=None, help="default: /frrobot/joint_states, else /joint_states")
    parser.add_argument("--command-topic", default=None,
                        help="default: /frrobot/joints_position_controller/command, else /fr5/arm_controller/command")
    parser.add_argument("--task", choices=TASK_NAMES, default=None, help="the replay's scene (config's)")
    parser.add_argument("--robot", choices=robot_names(), default=DEFAULT_ROBOT, help="the arm that made the run (fr5)")
    parser.add_argument("--force", action="store_true", help="replace an existing report in --out")
    return parser


def main(argv: Optional[List[str]] = None) -> int:
    args = build_parser().parse_args(script_args(argv))
    try:
        report_path = args.out / "report.json"
        if report_path.exists() and not args.force:
            raise FileExistsError(f"{report_path} exists; pass --force to replace it")
        settings = load_sim_to_real_settings()
        task = args.task or settings.task
        profile = load_driver_profile(args.driver_profile or settings.base_profile)
        spec = load_robot_spec(args.robot)
        recording = read_recording(args.bag, spec.joint_names, args.joint_states_topic, args.command_topic)
        result = replay_error(recording, profile, task, robot=args.robot)
        baseline = None
        baseline_replay = None
        if args.baseline_profile:
            base_profile = load_driver_profile(args.baseline_profile)
            baseline_result = replay_error(recording, base_profile, task, robot=args.robot)
            baseline_replay = baseline_result.pop("replay")
            baseline = {"profile": profile_summary(base_profile), "source": str(args.baseline_profile),
                        "tracking_error": baseline_result, "rms_ratio": baseline_result["rms_rad"] / max(result["rms_rad"], 1e-12)}
        replay = result.pop("replay")
        phase = result.pop("phase_steps")
        args.out.mkdir(parents=True, exist_ok=True)
        report = run_report(recording, replay, spec, {**profile_summary(profile), "source": profile.source},
                            result, phase, baseline)
        pictures = plot_joints(recording, replay, args.out, Path(args.bag).name, baseline_replay,
                               f"baseline ({args.baseline_profile})" if args.baseline_profile else "")
        report["pictures"] = {name: path.name for name, path in pictures.items()}
        write_json_atomic(report_path, report)
    except (ConfigError, RecordingError, FileExistsError) as error:
        return fail("compare_run.py", error)
    delay = report["estimated_delay_s"]
    print(f"compare_run.py: {recording.source}: {report['moving_s']:.1f} s of motion in {report['duration_s']:.1f} s, "
          f"{report['replayed_segments']} stretch(es) replayed behind {profile.source}")
    print(joint_table(result["per_joint"], spec.joint_names))
    print(f"all joints: RMS {math.degrees(result['rms_rad']):.4f} deg, max {math.degrees(result['max_rad']):.4f} deg; "
          f"delay recorded {1000 * delay['recorded']:.0f} ms, simulated {1000 * delay['simulated']:.0f} ms; "
          f"commands at a limit {100 * report['commands_at_limits']['any']:.1f} %")
    if baseline is not None:
        print(f"baseline {args.baseline_profile}: RMS {math.degrees(baseline['tracking_error']['rms_rad']):.4f} deg "
              f"({baseline['rms_ratio']:.1f}x this profile's)")
    print(f"compare_run.py: wrote {report_path} and {len(pictures)} pictures ({json.dumps(report['pictures'])})")
    return 0
