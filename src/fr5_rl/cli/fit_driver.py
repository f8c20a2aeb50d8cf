"""``rosrun fr5_rl fit_driver.py FILE.bag --out PROFILE.yaml``: fit the driver profile to the arm.

Fits what the simulator's model of the driver can express, from a recorded run: the servo
rate and the whole cycles of delay (each candidate replayed in the simulator), and per joint the
time constant of a first-order lag (the arm's response to its servo stream). Writes a profile
that the simulator node and training both read:

    roslaunch fr5_rl sim_policy.launch driver:=fairino driver_profile:=PROFILE.yaml
    rosrun fr5_rl train.py --task reach --driver-profile PROFILE.yaml

The profile keeps the base profile's other keys (topics, physics step, state rate); a file with
the same keys written by hand works the same way. PROFILE.fit.json beside it lists every
candidate tried.
"""
from __future__ import annotations

import argparse
import dataclasses
import math
from pathlib import Path
from typing import List, Optional

from ..env_config import TASK_NAMES
from ..config import DEFAULT_ROBOT, ConfigError, load_robot_spec, robot_names
from ..deploy.bundle import write_json_atomic
from ..sim.driver_profile import load_driver_profile, profile_summary, write_driver_profile
from ..sim_to_real.fit import fit_driver, load_sim_to_real_settings
from ..sim_to_real.recording import RecordingError, read_recording
from . import fail, parser_from_doc, script_args


def build_parser() -> argparse.ArgumentParser:
    parser = parser_from_doc("fit_driver.py", __doc__)
    parser.add_argument("bag", type=Path, help="a run recorded with record.launch (the policy node moving the arm)")
    parser.add_argument("--out", type=Path, required=True, help="the profile to write (YAML)")
    parser.add_argument("--base-profile", default=None,
                        help="the profile whose other keys the fitted one keeps (default: config/sim_to_real.yaml's)")
    parser.add_argument("--joint-states-topic", default=None)
    parser.add_argument("--command-topic", default=None)
    parser.add_argument("--task", choices=TASK_NAMES, default=None, help="the replay's scene (config's)")
    parser.add_argument("--robot", choices=robot_names(), default=DEFAULT_ROBOT, help="the arm that made the run (fr5)")
    parser.add_argument("--servo-rates", type=float, nargs="+", default=None, metavar="HZ",
                        help="also try these servo rates (default: config/sim_to_real.yaml's; the base profile's "
                             "rate is always tried)")
    parser.add_argument("--force", action="store_true", help="replace an existing profile")
    parser.add_argument("--quiet", action="store_true", help="no line per candidate")
    return parser


def main(argv: Optional[List[str]] = None) -> int:
    args = build_parser().parse_args(script_args(argv))
    try:
        if args.out.exists() and not args.force:
            raise FileExistsError(f"{args.out} exists; pass --force to replace it")
        settings = load_sim_to_real_settings()
        fit_settings = settings.fit
        if args.servo_rates is not None:
            fit_settings = dataclasses.replace(fit_settings, servo_rates=list(args.servo_rates))
        if fit_settings.loss not in ("mae", "mse"):
            raise ConfigError(f"config/sim_to_real.yaml: fit.loss must be mae or mse, got {fit_settings.loss!r}")
        base_name = args.base_profile or settings.base_profile
        base = load_driver_profile(base_name)
        spec = load_robot_spec(args.robot)
        recording = read_recording(args.bag, spec.joint_names, args.joint_states_topic, args.command_topic)
        print(f"fit_driver.py: {recording.source}: {recording.moving_time():.1f} s of motion; trying servo "
              f"rates, delays and phases behind {base_name}'s physics step ({1000 * base.physics_dt:g} ms)")
        result = fit_driver(recording, base, fit_settings, args.task or settings.task,
                            progress=None if args.quiet else print, robot=args.robot)
        fitted = result.profile
        taus = ", ".join(f"{1000 * tau:.1f}" for tau in fitted.response_time_constant_s)
        header = (f"Driver profile fitted by fit_driver.py to {recording.source}\n"
                  f"({recording.moving_time():.1f} s of motion; base {base_name}).\n"
                  f"servo {fitted.servo_rate:g} Hz, {fitted.servo_delay_cycles} cycle(s) of delay; response time "
                  f"constants (ms) {taus}.\n"
                  f"Replay error with it: {math.degrees(result.rms_rad):.4f} deg RMS (all joints).\n"
                  f"Use: roslaunch fr5_rl sim_policy.launch driver:=fairino driver_profile:={args.out}\n"
                  f"     rosrun fr5_rl train.py --driver-profile {args.out} ...")
        write_driver_profile(fitted, args.out, header, force=args.force)
        write_json_atomic(args.out.with_suffix(".fit.json"), {
            "bag": recording.source, "base_profile": str(base_name), "profile": profile_summary(fitted),
            "servo_phase_steps": result.phase_steps, "rms_rad": result.rms_rad, "per_joint": result.per_joint,
            "candidates": result.candidates})
    except (ConfigError, RecordingError, FileExistsError) as error:
        return fail("fit_driver.py", error)
    print(f"fit_driver.py: servo {fitted.servo_rate:g} Hz, delay {fitted.servo_delay_cycles} cycle(s), "
          f"response (ms) [{taus}]; replay error {math.degrees(result.rms_rad):.4f} deg RMS")
    print(f"fit_driver.py: wrote {args.out} and {args.out.with_suffix('.fit.json')}")
    return 0
