#!/usr/bin/env python3
"""Hash seeded rollouts of both tasks and every shipped model, to prove that a change of code
changed no behaviour: run it before and after, and compare the JSON (``--compare OLD.json``).

Each entry steps one environment for a fixed number of episodes from fixed seeds and hashes
every observation, reward, termination flag and the info's success/failure, in float64 bytes:
- ``<task>/random``: seeded random actions, the default env.yaml;
- ``<task>/randomised``: the same under the shipped randomisation of the task's training file;
- ``model/<name>``: the shipped model's deterministic policy on its training env overrides
  (randomisation included), and ``model/<name>/deployed`` on the overrides it is deployed with.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path
from typing import Any, Callable, Dict, Mapping

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "src"))


def _import_policy_loader():
    try:
        from fr5_rl.deploy.policy import load_policy  # the layout of issue #26
    except ImportError:  # the layout before it
        from fr5_rl.deploy.policy import load_policy
    return load_policy


def rollout_digest(task: str, overrides: Mapping[str, Any], act: Callable[[np.ndarray], np.ndarray],
                   seeds: range) -> Dict[str, Any]:
    """Digest of one episode per seed; ``act`` maps an observation to an action."""
    from fr5_rl.envs import FR5Env

    env = FR5Env(task=task, config=dict(overrides))
    digest = hashlib.sha256()
    steps = successes = 0
    for seed in seeds:
        obs, _ = env.reset(seed=int(seed))
        digest.update(np.asarray(obs, dtype=np.float64).tobytes())
        done = False
        while not done:
            obs, reward, terminated, truncated, info = env.step(act(obs))
            digest.update(np.asarray(obs, dtype=np.float64).tobytes())
            digest.update(np.float64(reward).tobytes())
            digest.update(bytes([terminated, truncated]))
            digest.update(str((bool(info["is_success"]), info["failure"])).encode())
            steps += 1
            done = terminated or truncated
        successes += bool(info["is_success"])
    env.close()
    return {"sha256": digest.hexdigest(), "steps": steps, "successes": successes}


# The randomisation of config/recipes/ppo_grasp_robust.yaml, written out so the digest does not move
# when config files do.
SHIPPED_RANDOMISATION = {
    "enabled": True, "action_latency_steps": [0, 2], "command_delay_s": [0.0, 0.02],
    "observation_age_s": [0.0, 0.02], "observation_noise_std": 0.005, "joint_damping": [0.0, 0.5],
    "object_size_scale": [0.9, 1.1], "object_mass_scale": [0.8, 1.2], "friction_scale": [0.8, 1.2],
    "plain_episode_share": 0.25,
}

# Every chain part the environment can draw at once, so that a change to one of them shows even
# where no shipped model trains on it: the driver's response, the bridged gripper (its timing
# model), the gripper's own latency, the camera's timing with its own action latency, the
# motion guard, velocities estimated from positions.
EVERY_CHAIN_PART = {
    "observation": {"joint_velocity_source": "positions", "previous_actions": 2},
    "randomisation": {**SHIPPED_RANDOMISATION, "response_time_constant_s": [0.02, 0.02, 0.03, 0.01, 0.01, 0.01],
                      "gripper_bridge_share": 0.6, "gripper_latency_steps": [0, 3], "target_share": 0.7,
                      "target_latency_s": [0.05, 0.2], "target_action_latency_steps": [1, 2],
                      "target_hidden_radius": 0.1, "guard_share": 0.5, "timing_share": 0.8,
                      "physics_dt_choices": [0.004, 0.005], "placement_focus_share": 0.3,
                      "placement_focus_low": [-0.7, -0.3], "placement_focus_high": [-0.6, 0.3]},
}


def random_actor(seed: int) -> Callable[[np.ndarray], np.ndarray]:
    rng = np.random.default_rng(seed)
    return lambda _obs: rng.uniform(-1.0, 1.0, 7)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--episodes", type=int, default=4, help="episodes per entry (default 4)")
    parser.add_argument("--out", type=Path, help="write the digests here (JSON)")
    parser.add_argument("--compare", type=Path, help="a JSON written before: exit 1 on any difference")
    args = parser.parse_args(argv)
    load_policy = _import_policy_loader()
    seeds = range(7_000_000, 7_000_000 + args.episodes)
    results: Dict[str, Any] = {}
    for task in ("reach", "grasp", "place"):
        results[f"{task}/random"] = rollout_digest(task, {}, random_actor(1), seeds)
        randomisation = {"randomisation": SHIPPED_RANDOMISATION}
        results[f"{task}/randomised"] = rollout_digest(task, randomisation, random_actor(2), seeds)
        results[f"{task}/every_chain_part"] = rollout_digest(task, EVERY_CHAIN_PART, random_actor(3), seeds)
    for model_dir in sorted(p for p in (ROOT / "models").iterdir() if (p / "meta.json").is_file()):
        policy = load_policy(model_dir)
        meta = json.loads((model_dir / "meta.json").read_text())
        act = policy.act
        results[f"model/{model_dir.name}"] = rollout_digest(policy.task, meta.get("env_overrides") or {}, act, seeds)
        results[f"model/{model_dir.name}/deployed"] = rollout_digest(
            policy.task, policy.deployment_overrides(), act, seeds)
    for name, entry in results.items():
        print(f"{name:32s} {entry['sha256'][:16]}  steps {entry['steps']:5d}  successes {entry['successes']}")
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(results, indent=2) + "\n")
    if args.compare:
        before = json.loads(args.compare.read_text())
        differ = sorted(name for name in set(before) | set(results) if before.get(name) != results.get(name))
        print("identical to " + str(args.compare) if not differ else "DIFFERENT: " + ", ".join(differ))
        return 1 if differ else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
