"""The real-time loop's timing, emulated in one process: how a model fares behind a driver.

    python tools/bench/timing.py [--model models/reach] [--episodes 600] [--seed 900000]
                                 [--profile fairino|default] [--compute-ms 2]

A ten-episode ROS run says little about a 90 % target: its confidence interval spans 55-100 %.
This bench reproduces, physics step by physics step, what the real-time loop of
``sim_policy.launch driver:=<profile>`` does, with the deployed code and none of the noise of
a ROS run, so 600 episodes take about 30 s:

- the simulator's profile (config/sim_node.yaml, + config/sim_node_fairino.yaml for fairino):
  physics step, joint-state publish rate (each message samples the arm when published), the
  servo cycle and its delay (src/fr5_rl/sim/servo.py, the simulator's own class);
- the policy node's step (deploy/deployment.py ``DeploymentStep``, its JointStateReader) at
  50 Hz with a random phase against the joint states, each command acting ``--compute-ms``
  after the period starts (``ros_loop.py`` measures the node's compute latency: p50 0.5 ms
  on a quiet machine, 1.7 ms with one core busy);
- the episode judged every control period from the first command, as the simulator does.

Every episode draws its own phases, so the results cover the timings a real run meets. Writes
bench/results/timing_<task>_<profile>.json. Target (issue #11): >= 90 % reach behind the
FAIRINO profile.
"""
import argparse
import sys
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence

import numpy as np

from benchlib import AT_LEAST, REPO, RESULTS_DIR, relative_path, update_summary, verdict, write_result

from fr5_rl.config import load_robot_spec, load_yaml, package_root, whole_multiple
from fr5_rl.env_config import load_env_config
from fr5_rl.envs import FR5Env
from fr5_rl.deploy.deployment import Command, DeploymentStep, StepInputs
from fr5_rl.deploy.joint_state import JointStateReader, Reading
from fr5_rl.deploy.policy import load_policy
from fr5_rl.sim.servo import ServoCycle
from fr5_rl.training.evaluation import wilson_interval

TARGET_SUCCESS = 0.9


def simulator_profile(profile: str) -> Dict[str, Any]:
    """The simulator node's parameters for ``profile``, as sim_policy.launch loads them."""
    params = dict(load_yaml(package_root() / "config" / "sim_node.yaml"))
    if profile == "fairino":
        params.update(load_yaml(package_root() / "config" / "sim_node_fairino.yaml"))
    return params


def run_episode(env: FR5Env, step: DeploymentStep, robot, seed: int, rng: np.random.Generator,
                params: Dict[str, Any], compute_s: float) -> Dict[str, Any]:
    """One episode of the real-time loop; its outcome and length in periods."""
    physics_dt = float(params["physics_dt"])
    per_period = whole_multiple(env.control_dt, physics_dt)
    per_publish = whole_multiple(1.0 / float(params["publish_rate"]), physics_dt)
    servo_rate = float(params["servo_rate"])
    servo = ServoCycle(whole_multiple(1.0 / servo_rate, physics_dt) if servo_rate else 0,
                       int(params["servo_delay_cycles"]), env.joint_positions())
    compute_steps = int(round(compute_s / physics_dt))
    env.reset(seed=seed)
    step.start_episode()
    reader = JointStateReader(robot.joint_names, robot.finger_joint_names)
    # Random phases: when the simulator publishes, and when the node's 50 Hz timer fires.
    publish_phase, policy_phase = int(rng.integers(per_publish)), int(rng.integers(per_period))
    arm_command: Optional[Sequence[float]] = None
    gripper_width = robot.max_opening_width
    pending: List[tuple] = []  # (physics step it arrives at, arm targets, gripper width)
    first_command_step: Optional[int] = None
    k = 0
    while True:
        now = k * physics_dt
        if (k + publish_phase) % per_publish == 0:
            js = env.joint_states()
            reader.update(js.names, js.positions, js.velocities, now, now)
        if (k + policy_phase) % per_period == 0:
            pose = env.object_pose()
            result = step(StepInputs(now, reader.reading(), Reading(tuple(pose.position), now, stamp=now), now))
            if isinstance(result, Command):
                pending.append((k + compute_steps, result.arm_positions, result.gripper_width))
        while pending and pending[0][0] <= k:
            _, arm_command, gripper_width = pending.pop(0)
            if first_command_step is None:
                first_command_step = k
        env.advance_physics(servo.targets_for_step(arm_command), gripper_width)
        k += 1
        if first_command_step is not None and (k - first_command_step) % per_period == 0:
            verdict_now = env.judge_period()
            if verdict_now.ended:
                return {"seed": seed, "success": bool(verdict_now.success), "failure": verdict_now.failure,
                        "steps": (k - first_command_step) // per_period}


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", default="models/reach")
    parser.add_argument("--episodes", type=int, default=600)
    parser.add_argument("--seed", type=int, default=900000, help="episode k places the object with seed + k")
    parser.add_argument("--profile", choices=("fairino", "default"), default="fairino")
    parser.add_argument("--backend", choices=("onnx", "torch"), default="onnx")
    parser.add_argument("--compute-ms", type=float, default=2.0, help="period start to command sent (ms)")
    parser.add_argument("--results", type=Path, default=RESULTS_DIR)
    args = parser.parse_args(argv)

    model_dir = Path(args.model) if Path(args.model).is_absolute() else REPO / args.model
    policy = load_policy(model_dir, args.backend)
    robot = load_robot_spec()
    params = simulator_profile(args.profile)
    task = policy.task
    env = FR5Env(task, config={task: {"simulation": {"physics_dt": float(params["physics_dt"]),
                                                     "solver_iterations": int(params["solver_iterations"])}}})
    node_cfg = load_yaml(package_root() / "config" / "policy_node.yaml")
    step = DeploymentStep(policy, robot, load_env_config(policy.meta.get("env_overrides", {})),
                          float(node_cfg["joint_state_timeout"]), float(node_cfg["target_timeout"]),
                          target_workspace_margin=float(node_cfg["target_workspace_margin"]),
                          future_stamp_tolerance=float(node_cfg["future_stamp_tolerance"]))
    rng = np.random.default_rng(args.seed)
    records = [run_episode(env, step, robot, args.seed + index, rng, params, args.compute_ms / 1000.0)
               for index in range(args.episodes)]
    env.close()
    successes = sum(record["success"] for record in records)
    failures: Dict[str, int] = {}
    for record in records:
        if not record["success"]:
            failures[str(record["failure"])] = failures.get(str(record["failure"]), 0) + 1
    rate = successes / len(records)
    low, high = wilson_interval(successes, len(records))
    print(f"{relative_path(model_dir)} behind the {args.profile} profile: {successes}/{len(records)} "
          f"({100 * rate:.1f} %, 95 % CI {100 * low:.1f}-{100 * high:.1f} %), failures {failures}")
    verdicts = {"success_rate": verdict(rate, TARGET_SUCCESS, AT_LEAST)}
    out = args.results / f"timing_{task}_{args.profile}.json"
    write_result(out, {"model": relative_path(model_dir), "profile": args.profile, "simulator": params,
                       "compute_ms": args.compute_ms, "episodes": len(records), "seed": args.seed,
                       "successes": successes, "success_rate": rate, "success_ci95": [low, high],
                       "failures": failures, "records": records}, verdicts)
    update_summary(args.results, f"timing_{task}_{args.profile}", out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
