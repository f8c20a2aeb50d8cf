#!/usr/bin/env python3
"""Environment steps per second of whichever ``fr5_rl`` this interpreter imports: the probe the
env bench runs under this checkout and under the previous release (tools/bench/reference.py),
alternately, so that both are timed on the same machine in the same minutes.

    python tools/bench/env_probe.py --task reach --variant randomised --steps 5000

Random actions in [-1, 1] (seeded), a reset whenever an episode ends (timed, as in the env
bench), after untimed warm-up steps. ``randomised`` takes the ``env`` section of the task's
training file from the imported package's own config (config/ppo_reach.yaml,
config/recipes/ppo_grasp_chain.yaml), read with PyYAML so that old and new code read it alike. Prints
one JSON line. Uses only ``FR5Env(task, config)``, ``reset(seed=)`` and ``step``: the API every
release has.
"""
from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np
import yaml

# env_and_inference.RANDOMISED_FROM by task name. Not imported from there: its benchlib puts this
# checkout's src first on the path, and the probe must import the release's fr5_rl.
RANDOMISED_FROM = {"reach": "ppo_reach", "grasp": "ppo_grasp_chain"}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", choices=sorted(RANDOMISED_FROM), required=True)
    parser.add_argument("--variant", choices=["plain", "randomised"], required=True)
    parser.add_argument("--steps", type=int, default=5000)
    parser.add_argument("--warmup", type=int, default=300)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    from fr5_rl.config import package_root
    from fr5_rl.envs import FR5Env

    overrides = None
    if args.variant == "randomised":
        name = f"{RANDOMISED_FROM[args.task]}.yaml"
        path = package_root() / "config" / name  # a release before config/recipes/ held its stages here
        if not path.is_file():
            path = package_root() / "config" / "recipes" / name
        with open(path, encoding="utf-8") as handle:
            overrides = yaml.safe_load(handle).get("env")
    env = FR5Env(args.task, overrides)
    actions = np.random.default_rng(args.seed).uniform(-1.0, 1.0, (args.warmup + args.steps, 7)).astype(np.float32)
    episode_seed = args.seed * 1_000_000
    env.reset(seed=episode_seed)

    def run(chunk: np.ndarray) -> None:
        nonlocal episode_seed
        for action in chunk:
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                episode_seed += 1
                env.reset(seed=episode_seed)

    run(actions[:args.warmup])
    start = time.perf_counter()
    run(actions[args.warmup:])
    seconds = time.perf_counter() - start
    env.close()
    print(json.dumps({"task": args.task, "variant": args.variant, "steps": args.steps, "seconds": seconds,
                      "steps_per_s": args.steps / seconds, "episodes": episode_seed - args.seed * 1_000_000 + 1}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
