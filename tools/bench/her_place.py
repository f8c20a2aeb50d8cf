#!/usr/bin/env python3
"""HER on pick-and-place, against the main recipe's clock: SAC or TQC with Stable-Baselines3's
``HerReplayBuffer`` on ``FR5PlaceGoal-v0``, in the world the main recipe learns in.

    python tools/bench/her_place.py --algo sac --minutes 30
    python tools/bench/her_place.py --algo tqc --minutes 30 --world quiet

The run learns for ``--minutes`` of wall time in chunks of ``--eval-every`` steps; after each chunk
the deterministic policy is judged on ``--eval-episodes`` held-out seeds (2,000,000+, never trained
on) of the task's whole success test (released, upright, at rest; not HER's goal-only reward). The
hyperparameters follow rl-zoo's for panda-gym's PickAndPlace (TQC + HER: future goals, 4 per
transition, gamma 0.95, tau 0.05, learning rate 1e-3), scaled to one process on this machine.

``--world deployed`` (default) is config/dagger_place.yaml's world (boxes and cylinders, the
deployed chain's timing, bridge, camera and guard); ``quiet`` is the same objects with only
observation noise, latency and mass/friction randomised. Writes bench/results/her_place_<algo>.json
(steps, wall time and success after each chunk).
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence

from benchlib import RESULTS_DIR, machine_info, write_result

EVAL_SEED = 2_000_000


def world_overrides(world: str) -> Dict[str, Any]:
    """The environment overrides of ``world`` (see the module's docstring)."""
    from fr5_rl.config import load_yaml

    overrides = dict(load_yaml("dagger_place")["env"])
    if world == "quiet":
        overrides["randomisation"] = {"enabled": True, "observation_noise_std": 0.003, "action_latency_steps": [0, 1],
                                      "object_mass_scale": [0.8, 1.2], "friction_scale": [0.8, 1.2],
                                      "object_size_scale": [1.0, 1.0], "joint_damping": [0.0, 0.5]}
    return overrides


def success_rate(model, overrides: Dict[str, Any], episodes: int) -> float:
    """Share of held-out episodes the deterministic policy completes (the task's whole test), in
    the task's world without randomisation."""
    from fr5_rl.goal_env import FR5PlaceGoalEnv

    plain = {key: value for key, value in overrides.items() if key != "randomisation"}
    env = FR5PlaceGoalEnv(config=plain)
    successes = 0
    for episode in range(episodes):
        observation, _ = env.reset(seed=EVAL_SEED + episode)
        done, info = False, {}
        while not done:
            action, _ = model.predict(observation, deterministic=True)
            observation, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
        successes += bool(info.get("is_success"))
    env.close()
    return successes / max(episodes, 1)


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--algo", choices=("sac", "tqc"), default="sac")
    parser.add_argument("--world", choices=("deployed", "quiet"), default="deployed")
    parser.add_argument("--minutes", type=float, default=30.0, help="wall-time budget for learning")
    parser.add_argument("--eval-every", type=int, default=10_000, help="environment steps between evaluations")
    parser.add_argument("--eval-episodes", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--results", type=Path, default=RESULTS_DIR)
    args = parser.parse_args(argv)

    import torch
    from stable_baselines3 import SAC, HerReplayBuffer

    from fr5_rl.goal_env import FR5PlaceGoalEnv

    torch.set_num_threads(1)
    overrides = world_overrides(args.world)
    env = FR5PlaceGoalEnv(config=overrides)
    algorithm = SAC
    if args.algo == "tqc":
        from sb3_contrib import TQC

        algorithm = TQC
    model = algorithm("MultiInputPolicy", env, replay_buffer_class=HerReplayBuffer,
                      replay_buffer_kwargs={"n_sampled_goal": 4, "goal_selection_strategy": "future"},
                      learning_rate=1e-3, buffer_size=1_000_000, batch_size=256, gamma=0.95, tau=0.05,
                      learning_starts=1000, policy_kwargs={"net_arch": [256, 256, 256]}, seed=args.seed,
                      device="cpu", verbose=0)
    started = time.monotonic()
    learning_s = 0.0
    history: List[Dict[str, Any]] = []
    while learning_s < args.minutes * 60.0:
        chunk = time.monotonic()
        model.learn(args.eval_every, reset_num_timesteps=False, progress_bar=False)
        learning_s += time.monotonic() - chunk
        rate = success_rate(model, overrides, args.eval_episodes)
        history.append({"steps": int(model.num_timesteps), "learning_wall_s": round(learning_s, 1),
                        "success": rate})
        print(f"{model.num_timesteps} steps, {learning_s / 60.0:.1f} min learning: success {rate:.0%} "
              f"on {args.eval_episodes} held-out episodes", flush=True)
    result = {"bench": "her_place", "algo": args.algo, "world": args.world, "seed": args.seed,
              "hyperparameters": {"n_sampled_goal": 4, "goal_selection_strategy": "future", "learning_rate": 1e-3,
                                  "batch_size": 256, "gamma": 0.95, "tau": 0.05, "net_arch": [256, 256, 256]},
              "eval_seeds_from": EVAL_SEED, "eval_episodes": args.eval_episodes, "history": history,
              "steps_per_s": round(model.num_timesteps / max(learning_s, 1e-9), 1),
              "wall_s": round(time.monotonic() - started, 1)}
    path = write_result(args.results / f"her_place_{args.algo}_{args.world}.json", result, machine=machine_info())
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
