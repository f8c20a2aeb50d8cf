#!/usr/bin/env python3
"""Benchmarks of fr5_rl: environment speed and policy inference latency (`make bench`).

    python tools/bench/env_and_inference.py            # full: 5000 steps x 3 repeats per task, 5000 inference calls
    python tools/bench/env_and_inference.py --quick    # smoke run: 1000 steps x 3 repeats, 1000 calls
    python tools/bench/env_and_inference.py --model runs/reach_ppo_x/final

Environment speed, for FR5Reach-v0 and FR5Grasp-v0 in one process, each plain (env.yaml) and
randomised (the env overrides of config/ppo_reach.yaml and config/recipes/ppo_grasp_chain.yaml): random
actions in [-1, 1] with a reset whenever an episode ends (resets are part of the timed loop,
warm-up steps are not), median of the repeats:

- env steps/s and the real-time factor (steps * control_dt / wall seconds);
- the ratio to bare PyBullet measured in the same run (issue #30 wants >= 0.7), against two
  references. Every motor command the env sent, with the physics steps it stood for, is
  recorded (an untimed second run: episodes are seeded one by one, so it is the same run;
  randomised timing and physics steps included) and replayed:
  - *bare world*: on the env's own world (robot, table, object), one
    ``setJointMotorControlArray`` per command and its ``stepSimulation`` calls, a bare reset per
    episode (the object asleep from its first physics step on, as the env's world puts it),
    nothing else; the replay ends with the joints the env ended with (the deviation
    is reported);
  - *bare URDF only*: the same commands on the robot's URDF alone (no table, no object): the
    reference of issue #30. The object costs physics time the env cannot avoid without
    changing its rollouts (it never quite sleeps on the table);
- for comparison, ``stepSimulation`` of the scene at rest right after a reset (nothing moves,
  the object sleeps), which is cheaper than the moving scene the env simulates;
- the floor: the replay plus the four simulator queries every step needs (joints, tcp link,
  object pose, contacts), their results unused;
- a minimal env: the floor plus the least Python any gymnasium env of these tasks runs per step
  (the action clipped, an observation array, a distance reward, a success test, an ``info``
  dict), with the bare reset and with this env's own reset: how near 0.7 a Python env on
  PyBullet can come at all.

Against the previous release (``--reference REV``, default tools/bench/reference_release.yaml;
``--no-reference`` skips it): tools/bench/env_probe.py runs the same random actions with resets
under this checkout and under that commit's code (tools/bench/reference.py), alternately,
``--repeats`` times each, in fresh processes; the ratio of the median steps/s (new / old) per
task and variant.

Inference latency of a model directory (default models/reach; skipped when absent): p50/p99
of single-observation ``Policy.act`` calls through ``fr5_rl.deploy.policy.load_policy`` for the torch
and onnx backends (the onnx graph is exported into a temporary copy when the directory has
none). Observations come from rollouts in the model's own environment.

Targets are printed as met / not met, never asserted. Results go to
bench/results/env_speed.json and bench/results/inference.json (each with its "verdicts"), and
this bench's entries of bench/results/summary.json are replaced (the other benches' are kept;
see tools/bench/benchlib.py). Only time.perf_counter is used for timing.
"""
from __future__ import annotations

import argparse
import math
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Dict, List, Optional

import numpy as np

from env_floor import record_episodes, run_seeded_episodes, replay_bare, replay_urdf_only, resting_step_seconds
from benchlib import (AT_LEAST, AT_MOST, REPO, RESULTS_DIR, latency_ms, machine_info, pass_fail, relative_path,
                      update_summary, verdict, write_result)

TARGETS = {
    "FR5Reach-v0": {"real_time_factor": 100.0},
    "FR5Grasp-v0": {"real_time_factor": 50.0},
    "overhead_max": 1.3,
    "onnx_p99_ms_max": 0.2,
}


def env_verdicts(environments: Dict[str, Dict[str, Any]]) -> Dict[str, Dict[str, Any]]:
    """Per environment: real-time factor at least its target, overhead at most 1.3x."""
    verdicts = {}
    for env_id, r in sorted(environments.items()):
        verdicts[f"{env_id}.real_time_factor"] = verdict(
            r["real_time_factor"], TARGETS[env_id]["real_time_factor"], AT_LEAST, "x", f"{env_id} real-time factor")
        verdicts[f"{env_id}.overhead"] = verdict(
            r["overhead"], TARGETS["overhead_max"], AT_MOST, "x", f"{env_id} env time / bare PyBullet")
    return verdicts


def inference_verdicts(result: Dict[str, Any]) -> Dict[str, Dict[str, Any]]:
    """onnx p99 at most 0.2 ms; none when the bench was skipped."""
    if result.get("skipped"):
        return {}
    return {"onnx_p99_ms": verdict(result["backends"]["onnx"]["p99_ms"], TARGETS["onnx_p99_ms_max"], AT_MOST, "ms",
                                   f"{result.get('task')} policy inference (onnx) p99")}


# ----------------------------------------------------------------------------- env speed
RANDOMISED_FROM = {"FR5Reach-v0": "ppo_reach", "FR5Grasp-v0": "ppo_grasp_chain"}


def env_overrides(env_id: str, variant: str) -> Dict[str, Any]:
    """``plain``: the default env.yaml; ``randomised``: the env overrides of the task's training
    file (:data:`RANDOMISED_FROM`), its randomisation included."""
    if variant == "plain":
        return {}
    from fr5_rl.training.hyperparameters import read_hyperparameter_file

    return read_hyperparameter_file(RANDOMISED_FROM[env_id]).get("env") or {}


def bench_env(env_id: str, steps: int, repeats: int, warmup: int, seed: int = 0,
              variant: str = "plain") -> Dict[str, Any]:
    from fr5_rl.envs import FR5Env

    task = {"FR5Reach-v0": "reach", "FR5Grasp-v0": "grasp"}[env_id]
    overrides = env_overrides(env_id, variant)
    env = FR5Env(task=task, config=overrides or None)
    substeps = env.plant.world.substeps
    rng = np.random.default_rng(seed)
    actions = rng.uniform(-1.0, 1.0, size=(steps + warmup, 7)).astype(np.float32)
    timed_actions = actions[warmup:]

    per_repeat = []
    for repeat in range(repeats):
        first_seed = seed + 100_000 * repeat
        run_seeded_episodes(env, actions[:warmup], first_seed + 50_000)  # warm-up, not timed
        t0 = time.perf_counter()
        seeds = run_seeded_episodes(env, timed_actions, first_seed)
        env_s = time.perf_counter() - t0

        episodes = record_episodes(env, timed_actions, first_seed)
        if [e["seed"] for e in episodes] != seeds or sum(e["steps"] for e in episodes) != steps:
            raise RuntimeError("the recording run differs from the timed run: the environment is not deterministic")
        physics_steps = sum(n for e in episodes for _, n in e["commands"])
        replay = replay_bare(env, episodes)
        floor = replay_bare(env, episodes, with_queries=True)
        minimal = replay_bare(env, episodes, minimal_env=True)
        minimal_with_reset_s = minimal["seconds"] + minimal["env_reset_seconds"]
        urdf = replay_urdf_only(env, episodes)
        urdf_s = urdf["seconds"]
        resting_s = resting_step_seconds(env, steps, first_seed)
        per_repeat.append({
            "env_seconds": round(env_s, 4),
            "episodes": len(seeds),
            "physics_steps": physics_steps,
            "steps_per_s": steps / env_s,
            "real_time_factor": steps * env.control_dt / env_s,
            "env_step_us": 1e6 * env_s / steps,
            "bare_replay_seconds": round(replay["seconds"], 4),
            "bare_replay_step_us": 1e6 * replay["seconds"] / steps,
            "bare_replay_steps_per_s": steps / replay["seconds"],
            "bare_replay_max_final_joint_deviation_rad": replay["max_final_joint_deviation_rad"],
            "overhead": env_s / replay["seconds"],
            "ratio_to_bare_world": replay["seconds"] / env_s,
            "bare_urdf_only_step_us": 1e6 * urdf_s / steps,
            "bare_urdf_only_steps_per_s": steps / urdf_s,
            "ratio_to_bare_urdf_only": urdf_s / env_s,
            "bare_urdf_only_untouched_episodes_same_motion": urdf["same_motion_share"],
            "bare_replay_with_queries_step_us": 1e6 * floor["seconds"] / steps,
            "overhead_floor_with_queries": floor["seconds"] / replay["seconds"],
            "ratio_of_floor_to_bare_urdf_only": urdf_s / floor["seconds"],
            "minimal_env_step_us": 1e6 * minimal["seconds"] / steps,
            "ratio_of_minimal_env_to_bare_urdf_only": urdf_s / minimal["seconds"],
            "env_reset_us": 1e6 * minimal["env_reset_seconds"] / len(episodes),
            "ratio_of_minimal_env_with_this_reset_to_bare_urdf_only": urdf_s / minimal_with_reset_s,
            "resting_physics_substep_us": 1e6 * resting_s / (steps * substeps),
            "overhead_over_resting_scene": env_s / resting_s,
        })

    control_dt = env.control_dt
    env.close()

    def median(key: str) -> float:
        values = [r[key] for r in per_repeat if not math.isnan(r[key])]  # NaN: a repeat had nothing to compare
        return float(statistics.median(values)) if values else float("nan")

    rtf = median("real_time_factor")
    overhead = median("overhead")
    met = env_verdicts({env_id: {"real_time_factor": rtf, "overhead": overhead}})
    return {
        "env_id": env_id,
        "variant": variant,
        "env_overrides_from": None if variant == "plain" else f"config/{RANDOMISED_FROM[env_id]}.yaml",
        "steps_per_repeat": steps,
        "repeats": repeats,
        "warmup_steps": warmup,
        "control_dt": control_dt,
        "substeps": substeps,
        **{key: median(key) for key in (
            "steps_per_s", "real_time_factor", "env_step_us", "bare_replay_step_us", "bare_replay_steps_per_s",
            "overhead", "ratio_to_bare_world", "bare_urdf_only_step_us", "bare_urdf_only_steps_per_s",
            "ratio_to_bare_urdf_only", "bare_urdf_only_untouched_episodes_same_motion", "bare_replay_with_queries_step_us",
            "overhead_floor_with_queries", "ratio_of_floor_to_bare_urdf_only", "minimal_env_step_us",
            "ratio_of_minimal_env_to_bare_urdf_only", "env_reset_us",
            "ratio_of_minimal_env_with_this_reset_to_bare_urdf_only", "resting_physics_substep_us",
            "overhead_over_resting_scene")},
        "per_repeat": per_repeat,
        "targets": {
            "real_time_factor_min": TARGETS[env_id]["real_time_factor"],
            "real_time_factor": pass_fail(met[f"{env_id}.real_time_factor"]),
            "overhead_max": TARGETS["overhead_max"],
            "overhead": pass_fail(met[f"{env_id}.overhead"]),
        },
    }


# ----------------------------------------------------------------------------- inference
def rollout_observations(task: str, env_overrides: Dict[str, Any], count: int, seed: int = 7) -> np.ndarray:
    """``count`` raw observations from random-action rollouts of the model's environment."""
    from fr5_rl.envs import FR5Env

    env = FR5Env(task=task, config=env_overrides or None)
    rng = np.random.default_rng(seed)
    obs, _ = env.reset(seed=seed)
    observations = []
    while len(observations) < count:
        observations.append(obs.copy())
        obs, _, terminated, truncated, _ = env.step(rng.uniform(-1, 1, 7).astype(np.float32))
        if terminated or truncated:
            obs, _ = env.reset()
    env.close()
    return np.stack(observations)


def time_calls(act, observations: np.ndarray, calls: int, warmup: int = 200) -> Dict[str, float]:
    perf = time.perf_counter
    n = len(observations)
    for i in range(warmup):
        act(observations[i % n])
    samples = np.empty(calls)
    for i in range(calls):
        obs = observations[i % n]
        t0 = perf()
        act(obs)
        samples[i] = perf() - t0
    return {"calls": calls, **latency_ms(samples, points=(50, 90, 99), mean=True)}


def bench_inference(model_dir: Optional[Path], calls: int) -> Dict[str, Any]:
    if model_dir is None or not model_dir.is_dir():
        return {"skipped": True, "reason": f"no model directory at {model_dir}"}
    from fr5_rl.deploy.bundle import ONNX_FILE, ModelFilesError
    from fr5_rl.deploy.policy import load_policy

    result: Dict[str, Any] = {"model_dir": relative_path(model_dir), "backends": {}}
    work = model_dir
    tmp = None
    try:
        torch_policy = load_policy(model_dir, "torch")
    except ModelFilesError as error:
        return {"skipped": True, "reason": str(error), "model_dir": relative_path(model_dir)}
    observations = rollout_observations(torch_policy.task, torch_policy.meta.get("env_overrides", {}),
                                        min(calls, 2000))
    result.update({"task": torch_policy.task, "algo": torch_policy.meta.get("algo"),
                   "observation_size": torch_policy.observation_size})
    result["backends"]["torch"] = time_calls(torch_policy.act, observations, calls)
    try:
        if not (model_dir / ONNX_FILE).is_file():
            from fr5_rl.training.onnx_export import export

            tmp = Path(tempfile.mkdtemp(prefix="fr5_bench_"))
            work = tmp / model_dir.name
            shutil.copytree(model_dir, work)
            export(work)
            result["onnx_exported_to_temporary_copy"] = True
        onnx_policy = load_policy(work, "onnx")
        result["backends"]["onnx"] = time_calls(onnx_policy.act, observations, calls)
        worst = max(float(np.max(np.abs(torch_policy.act(o) - onnx_policy.act(o)))) for o in observations[:500])
        result["onnx_max_abs_action_difference"] = worst
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
    result["targets"] = {"onnx_p99_ms_max": TARGETS["onnx_p99_ms_max"],
                         "onnx_p99": pass_fail(inference_verdicts(result)["onnx_p99_ms"])}
    return result


# ----------------------------------------------------------------------------- output
def print_env_table(rows: List[Dict[str, Any]]) -> None:
    header = (f"{'environment':<13} {'variant':<10} {'steps/s':>8} {'x real time':>12}  {'env step':>9} "
              f"{'bare world':>11} {'ratio':>6} {'bare urdf':>10} {'ratio':>6}")
    print(header)
    print("-" * len(header))
    for r in rows:
        print(f"{r['env_id']:<13} {r['variant']:<10} {r['steps_per_s']:>8.0f} {r['real_time_factor']:>11.1f}x  "
              f"{r['env_step_us']:>7.0f}us {r['bare_replay_steps_per_s']:>9.0f}/s {r['ratio_to_bare_world']:>5.2f}x "
              f"{r['bare_urdf_only_steps_per_s']:>8.0f}/s {r['ratio_to_bare_urdf_only']:>5.2f}x")
    print("ratio = env steps/s / bare steps/s, measured in this run (>= 0.7 wanted): 'bare world' replays the env's "
          "motor commands in its own world (robot, table, object) with a bare reset per episode; 'bare urdf' the "
          "same commands on the URDF alone (no table, no object). Both: same physics step, solver iterations, "
          "joint speed cap, substeps, position targets every period, resets at the same episode lengths.")
    for r in rows:
        print(f"{r['env_id']} {r['variant']}: {r['env_step_us']:.0f}us per env step (resets included), the bare world "
              f"{r['bare_replay_step_us']:.0f}us ({r['substeps']} substeps plain), the bare world plus the four "
              f"state queries an env needs {r['bare_replay_with_queries_step_us']:.0f}us "
              f"({r['overhead_floor_with_queries']:.2f}x, the floor for a Python env; "
              f"{r['ratio_of_floor_to_bare_urdf_only']:.2f} of the URDF alone's speed); a minimal Python env on "
              f"that floor {r['minimal_env_step_us']:.0f}us ({r['ratio_of_minimal_env_to_bare_urdf_only']:.2f} of "
              f"the URDF alone's speed; {r['ratio_of_minimal_env_with_this_reset_to_bare_urdf_only']:.2f} with this "
              f"env's resets, {r['env_reset_us']:.0f}us each); the resting scene steps in "
              f"{r['resting_physics_substep_us']:.0f}us per substep; the URDF alone moved as the env's arm in "
              f"{100 * r['bare_urdf_only_untouched_episodes_same_motion']:.0f} % of the episodes where that touched "
              "nothing")
    verdicts = env_verdicts({r["env_id"]: r for r in rows if r["variant"] == "plain"})
    print("targets (plain): " + ", ".join(f"{name} {v['verdict']}" for name, v in sorted(verdicts.items()))
          + f" (reach >= {TARGETS['FR5Reach-v0']['real_time_factor']:.0f}x real time, grasp >= "
          f"{TARGETS['FR5Grasp-v0']['real_time_factor']:.0f}x, overhead <= {TARGETS['overhead_max']}x over the bare "
          "world); median of repeats")


def bench_against_release(revision: str, steps: int, repeats: int) -> Dict[str, Any]:
    """Steps/s of this code and of ``revision``'s, by :mod:`env_probe`, alternating old and new
    (which goes first alternates too) so that a machine getting slower or faster mid-run
    touches both alike."""
    import json
    import subprocess

    from reference import ReferenceUnavailable, alternating, reference_environment, reference_tree, resolve

    try:
        tree, commit = reference_tree(revision), resolve(revision)
    except ReferenceUnavailable as error:
        print(f"\nagainst the release: skipped, {error}")
        return {"skipped": True, "reason": str(error)}
    probe = str(Path(__file__).resolve().parent / "env_probe.py")
    environments = {"new": None, "old": reference_environment(tree)}
    rows = []
    for task in ("reach", "grasp"):
        for variant in ("plain", "randomised"):
            measured: Dict[str, List[float]] = {"new": [], "old": []}
            for repeat in range(repeats):
                for which in alternating(repeat):
                    output = subprocess.run(
                        [sys.executable, probe, "--task", task, "--variant", variant, "--steps", str(steps),
                         "--seed", str(repeat)], env=environments[which], capture_output=True, text=True, check=True)
                    measured[which].append(json.loads(output.stdout.strip().splitlines()[-1])["steps_per_s"])
            new, old = statistics.median(measured["new"]), statistics.median(measured["old"])
            rows.append({"task": task, "variant": variant, "new_steps_per_s": round(new, 1),
                         "old_steps_per_s": round(old, 1), "new_over_old": round(new / old, 3),
                         "new_per_repeat": [round(v, 1) for v in measured["new"]],
                         "old_per_repeat": [round(v, 1) for v in measured["old"]]})
    print(f"\nagainst the release {revision} (commit {commit[:12]}), median of {repeats} alternating "
          f"runs of {steps} steps each, resets included:")
    print(f"{'task':<7} {'variant':<11} {'new':>9} {'old':>9} {'new/old':>8}")
    for r in rows:
        print(f"{r['task']:<7} {r['variant']:<11} {r['new_steps_per_s']:>7.0f}/s {r['old_steps_per_s']:>7.0f}/s "
              f"{r['new_over_old']:>7.2f}x")
    return {"release": revision, "commit": commit, "steps": steps, "repeats": repeats, "rows": rows}


def print_inference_table(result: Dict[str, Any]) -> None:
    if result.get("skipped"):
        print(f"inference latency: skipped ({result['reason']})")
        return
    print(f"inference latency, {result['model_dir']} ({result['task']}, {result['algo']}), single observation:")
    header = f"{'backend':<8} {'p50':>9} {'p90':>9} {'p99':>9} {'mean':>9} {'max':>9}  target"
    print(header)
    print("-" * len(header))
    for backend, s in result["backends"].items():
        target = inference_verdicts(result)["onnx_p99_ms"]["verdict"] if backend == "onnx" else ""
        print(f"{backend:<8} {s['p50_ms']:>7.3f}ms {s['p90_ms']:>7.3f}ms {s['p99_ms']:>7.3f}ms "
              f"{s['mean_ms']:>7.3f}ms {s['max_ms']:>7.3f}ms  {target}")
    print(f"target: onnx p99 <= {TARGETS['onnx_p99_ms_max']} ms; max |action torch - onnx| = "
          f"{result.get('onnx_max_abs_action_difference', float('nan')):.1e}")


def main(argv: Optional[List[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="1000 steps per repeat, 1000 inference calls")
    parser.add_argument("--steps", type=int, default=None, help="timed env steps per repeat (default 5000)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--warmup", type=int, default=300, help="untimed env steps before each repeat")
    parser.add_argument("--calls", type=int, default=None, help="inference calls per backend (default 5000)")
    parser.add_argument("--model", type=Path, default=None, help="model directory (default models/reach)")
    parser.add_argument("--skip-env", action="store_true")
    parser.add_argument("--reference", default=None,
                        help="the release to compare env speed against (default: tools/bench/reference_release.yaml)")
    parser.add_argument("--no-reference", action="store_true", help="skip the comparison with the release")
    parser.add_argument("--skip-inference", action="store_true")
    parser.add_argument("--results", type=Path, default=RESULTS_DIR,
                        help="output directory (default bench/results); its summary.json is updated")
    args = parser.parse_args(argv)
    steps = args.steps or (1000 if args.quick else 5000)
    calls = args.calls or (1000 if args.quick else 5000)

    written: List[Path] = []
    machine = machine_info()
    print(f"machine: {machine['cpu']}, {machine['cores']} cores ({machine['cores_usable']} usable), "
          f"load {machine.get('load_average_1min_at_start', '?')}; python {machine['python']}, "
          f"pybullet {machine.get('pybullet', '?')}")
    if not args.skip_env:
        rows = [bench_env(env_id, steps, args.repeats, args.warmup, variant=variant)
                for env_id in ("FR5Reach-v0", "FR5Grasp-v0") for variant in ("plain", "randomised")]
        print()
        print_env_table(rows)
        environments = {r["env_id"]: r for r in rows if r["variant"] == "plain"}
        environments_randomised = {r["env_id"]: r for r in rows if r["variant"] == "randomised"}
        env_result = {"quick": args.quick, "machine": machine, "environments": environments,
                      "environments_randomised": environments_randomised}
        if not args.no_reference:
            from reference import reference_release

            env_result["against_release"] = bench_against_release(args.reference or reference_release(), steps,
                                                                  args.repeats)
        if hasattr(os, "getloadavg"):
            env_result["machine"] = dict(machine, load_average_1min_at_end=round(os.getloadavg()[0], 2))
        written.append(write_result(args.results / "env_speed.json", env_result, env_verdicts(environments)))
    if not args.skip_inference:
        model_dir = args.model or (REPO / "models" / "reach")
        if args.model is None and not model_dir.is_dir():
            print(f"\ninference latency: skipped, {relative_path(model_dir)} does not exist "
                  "(train one or pass --model DIR)")
            result: Dict[str, Any] = {"skipped": True, "reason": f"{relative_path(model_dir)} does not exist"}
        else:
            result = bench_inference(model_dir, calls)
            print()
            print_inference_table(result)
        result.update({"quick": args.quick, "machine": machine})
        written.append(write_result(args.results / "inference.json", result, inference_verdicts(result)))
    for path in list(written):
        summary = update_summary(args.results, path.stem, path)
    if written:
        written.append(summary)
    print(f"\nwrote {', '.join(os.path.relpath(path) for path in written)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
