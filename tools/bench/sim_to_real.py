#!/usr/bin/env python3
"""Proof of the sim-to-real tools on the rehearsal: a driver the tools are not told is recovered.

1. The rehearsal (``sim_policy.launch driver:=fairino``, reach) runs behind a hand-written
   driver profile that differs from the shipped one (``--hidden``: more servo delay and a lag per
   joint), and ``record.launch`` records it, as it would a real arm.
2. ``fit_driver.py`` fits a profile to the bag (it is told nothing but the vendor profile's
   physics step and state rate).
3. ``compare_run.py`` replays the bag behind the shipped profile, the fitted one and the hidden
   one: the fitted must cut the error by >= 5x against the shipped profile.

    python tools/bench/sim_to_real.py [--hidden FILE] [--episodes 6] [--seed 1200000]

Writes RESULTS/sim_to_real.json, the bag, the fitted profile and compare_run's pictures (fitted
against shipped) to RESULTS (default docs/bench/sim_to_real).
"""
from __future__ import annotations

import argparse
import math
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from benchlib import REPO, print_verdicts, verdict, write_result  # noqa: E402
from roslaunch_run import SideLaunch, run_launch  # noqa: E402

from fr5_rl.config import load_robot_spec  # noqa: E402
from fr5_rl.sim.driver_profile import load_driver_profile, profile_summary, write_driver_profile  # noqa: E402
from fr5_rl.sim_to_real.fit import load_sim_to_real_settings, fit_driver  # noqa: E402
from fr5_rl.sim_to_real.replay import replay_error  # noqa: E402
from fr5_rl.sim_to_real.recording import read_recording  # noqa: E402


def record_rehearsal(hidden: Path, bag: Path, episodes: int, seed: int, port: int) -> dict:
    """Run the rehearsal behind ``hidden`` with record.launch beside it; return the run's figures."""
    recorder = SideLaunch("record.launch", {"bag": bag}, port)

    def start_recorder():
        recorder.start()
        time.sleep(2.0)  # subscribed before the policy's first episode is far along
        return []

    try:
        run = run_launch({"rviz": False, "driver": "fairino", "driver_profile": hidden, "model": "models/reach",
                          "task": "reach", "episodes": episodes, "seed": seed, "controller_port": port + 8700},
                         port=port, episodes=episodes,
                         listen=start_recorder)
    finally:
        recorder.stop()
    return {"episodes": run.episodes, "successes": run.successes, "wall_s": round(run.wall_s, 1)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--hidden", type=Path, default=REPO / "docs/bench/sim_to_real/hidden_profile.yaml",
                        help="the profile the rehearsal runs behind (the tools are not told)")
    parser.add_argument("--episodes", type=int, default=6)
    parser.add_argument("--seed", type=int, default=1_200_000)
    parser.add_argument("--port", type=int, default=11631)
    parser.add_argument("--results", type=Path, default=REPO / "docs/bench/sim_to_real")
    parser.add_argument("--bag", type=Path, default=None, help="fit this bag instead of recording one")
    args = parser.parse_args()
    args.results.mkdir(parents=True, exist_ok=True)
    hidden = load_driver_profile(args.hidden)
    bag = args.bag or args.results / "rehearsal.bag"
    rehearsal = None
    if args.bag is None:
        bag.unlink(missing_ok=True)
        rehearsal = record_rehearsal(args.hidden.resolve(), bag.resolve(), args.episodes, args.seed, args.port)
    settings = load_sim_to_real_settings()
    fit_settings = settings.fit
    base = load_driver_profile(settings.base_profile)
    recording = read_recording(bag, load_robot_spec().joint_names)
    started = time.time()
    fit = fit_driver(recording, base, fit_settings, settings.task, progress=print)
    fit_s = time.time() - started
    fitted_path = args.results / "fitted_profile.yaml"
    write_driver_profile(fit.profile, fitted_path, f"fitted by tools/bench/sim_to_real.py to {bag.name}", force=True)
    errors = {name: replay_error(recording, profile, settings.task)
              for name, profile in (("shipped", base), ("fitted", fit.profile), ("hidden", hidden))}
    for entry in errors.values():
        entry.pop("replay")
    # The pictures as a user makes them: the command line, fitted against shipped.
    def shown(path: Path) -> str:  # paths in the report as the repository's, where they are in it
        path = path.resolve()
        return str(path.relative_to(REPO)) if path.is_relative_to(REPO) else str(path)

    subprocess.run([sys.executable, str(REPO / "scripts" / "compare_run.py"), shown(bag), "--out",
                    shown(args.results / "gap"), "--driver-profile", shown(fitted_path), "--baseline-profile",
                    settings.base_profile, "--force"], check=True, cwd=REPO)
    tau_errors_ms = [1000.0 * (f - h) for f, h in zip(fit.profile.response_time_constant_s,
                                                       hidden.response_time_constant_s)]
    ratio = errors["shipped"]["rms_rad"] / max(errors["fitted"]["rms_rad"], 1e-12)
    verdicts = {
        "delay_cycles_exact": verdict(float(fit.profile.servo_delay_cycles == hidden.servo_delay_cycles), 1.0, "at least"),
        "response_within_3_ms": verdict(max(abs(e) for e in tau_errors_ms), 3.0, "at most", "ms"),
        "rms_cut_vs_shipped": verdict(ratio, 5.0, "at least", "x"),
    }
    result = {
        "bag": bag.name, "rehearsal": rehearsal, "moving_s": round(recording.moving_time(), 1),
        "hidden_profile": profile_summary(hidden), "fitted_profile": profile_summary(fit.profile),
        "response_error_ms": [round(e, 2) for e in tau_errors_ms], "fit_wall_s": round(fit_s, 1),
        "fit_candidates": fit.candidates,
        "replay_rms_deg": {name: math.degrees(entry["rms_rad"]) for name, entry in errors.items()},
        "replay_max_deg": {name: math.degrees(entry["max_rad"]) for name, entry in errors.items()},
        "rms_ratio_shipped_over_fitted": ratio,
    }
    path = write_result(args.results / "sim_to_real.json", result, verdicts)
    print(f"hidden {profile_summary(hidden)}\nfitted {profile_summary(fit.profile)}")
    print("replay RMS (deg): " + ", ".join(f"{k} {v:.4f}" for k, v in result["replay_rms_deg"].items()))
    print_verdicts(verdicts)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
