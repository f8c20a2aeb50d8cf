"""Shared by the gripper tests: the fingers told to close, step by step, in a bridge episode."""
from typing import List, Tuple

import numpy as np


def close_reading_back(env, steps: int) -> Tuple[List[float], List[float]]:
    """Step ``env`` (reset, its gripper behind a bridge) ``steps`` times with the fingers told to
    close and the arm still: the opening read back (m) and the fingers' own opening (m) after each."""
    close = np.zeros(7)
    close[6] = -1.0
    read_back, fingers = [], []
    for _ in range(steps):
        env.step(close)
        read_back.append(env.episode.chain.bridge.read_width)
        fingers.append(sum(env.episode.joint_states().positions[6:]))
    return read_back, fingers
