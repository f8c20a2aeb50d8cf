"""FR5PlaceGoal-v0: the place task as gymnasium-robotics' goal-conditioned API, for HER.

The observation is a dict, as Stable-Baselines3's ``HerReplayBuffer`` expects:

- ``observation``: the place environment's vector without its goal block;
- ``achieved_goal``: where the object is: (x, y) in m, base_link, ``(sin kψ, cos kψ)`` of its
  yaw ψ by its top's symmetry order ``k`` (``(0, 0)`` for a cylinder), and ``k / 4``;
- ``desired_goal``: the same of the goal.

:meth:`FR5PlaceGoalEnv.compute_reward` is vectorised and depends on the goals alone, so HER can
relabel any transition: 0 where the object is within ``place.position_tolerance`` of the goal and,
for a box, within ``place.yaw_tolerance_deg`` of its yaw (modulo the symmetry), else -1.
``info["is_success"]`` is the task's whole test (released, upright, at rest as well).
"""
from __future__ import annotations

import math
from typing import Any, Dict, Mapping, Optional, Tuple, Union

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from .env_config import EnvConfig
from .envs import FR5Env
from .objects import yaw_of
from .observation import GOAL_SIZE

GOAL_VECTOR_SIZE = 5  # x, y, sin k*yaw, cos k*yaw, k / 4


class FR5PlaceGoalEnv(gym.Env):
    """The place task with dict observations and a goal-only reward (HER).

    :param config: overrides merged into ``config/env.yaml``, or an :class:`EnvConfig`.
    :param robot: the arm (``config/robots/``); None: the configuration's.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 50}

    def __init__(self, config: Union[EnvConfig, Mapping[str, Any], None] = None, robot: Optional[str] = None,
                 render_mode: Optional[str] = None) -> None:
        super().__init__()
        self.env = FR5Env("place", config=config, render_mode=render_mode, robot=robot)
        self.render_mode = render_mode
        place = self.env.cfg.place
        self.position_tolerance = place.position_tolerance
        self.yaw_tolerance = math.radians(place.yaw_tolerance_deg)
        size = self.env.observation_space.shape[0] - GOAL_SIZE
        # x, y (m, base_link: within any arm's reach), sin, cos, k / 4.
        goal_space = spaces.Box(np.array([-2.0, -2.0, -1.0, -1.0, 0.0], dtype=np.float32),
                                np.array([2.0, 2.0, 1.0, 1.0, 1.0], dtype=np.float32), dtype=np.float32)
        self.observation_space = spaces.Dict({
            "observation": spaces.Box(-1.0, 1.0, (size,), dtype=np.float32),
            "achieved_goal": goal_space, "desired_goal": goal_space})
        self.action_space = self.env.action_space

    def _goal_vector(self, x: float, y: float, yaw: float) -> np.ndarray:
        order = self.env.episode.plant.object_shape.symmetry_order
        sine, cosine = (math.sin(order * yaw), math.cos(order * yaw)) if order else (0.0, 0.0)
        return np.array([x, y, sine, cosine, order / 4.0], dtype=np.float32)

    def _observe(self, flat: np.ndarray) -> Dict[str, np.ndarray]:
        state = self.env.episode.state
        achieved = self._goal_vector(state.object_position[0], state.object_position[1],
                                     yaw_of(state.object_quaternion))
        goal_x, goal_y, goal_yaw = self.env.episode.draws.goal
        return {"observation": flat[:-GOAL_SIZE].copy(), "achieved_goal": achieved,
                "desired_goal": self._goal_vector(goal_x, goal_y, goal_yaw)}

    def reset(self, *, seed: Optional[int] = None, options: Optional[Dict[str, Any]] = None
              ) -> Tuple[Dict[str, np.ndarray], Dict[str, Any]]:
        super().reset(seed=seed)
        flat, info = self.env.reset(seed=seed, options=options)
        return self._observe(flat), info

    def step(self, action: np.ndarray) -> Tuple[Dict[str, np.ndarray], float, bool, bool, Dict[str, Any]]:
        flat, _, terminated, truncated, info = self.env.step(action)
        observation = self._observe(flat)
        reward = float(self.compute_reward(observation["achieved_goal"], observation["desired_goal"], info))
        return observation, reward, terminated, truncated, info

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> np.ndarray:
        """0 where the goal is reached (position, and a box's yaw modulo its symmetry), else -1;
        vectorised over a batch of goals (HER's relabelling)."""
        achieved, desired = np.atleast_2d(achieved_goal), np.atleast_2d(desired_goal)
        near = np.hypot(achieved[:, 0] - desired[:, 0], achieved[:, 1] - desired[:, 1]) <= self.position_tolerance
        order = np.rint(desired[:, 4] * 4.0)
        # k times the yaw error, from the two (sin, cos) pairs; a cylinder's (0, 0) has none.
        encoded = np.abs(np.arctan2(achieved[:, 2] * desired[:, 3] - achieved[:, 3] * desired[:, 2],
                                    achieved[:, 2] * desired[:, 2] + achieved[:, 3] * desired[:, 3]))
        aligned = (order == 0) | (encoded <= order * self.yaw_tolerance)
        reward = np.where(near & aligned, 0.0, -1.0).astype(np.float32)
        return reward if np.ndim(achieved_goal) > 1 else reward[0]

    def render(self) -> Optional[np.ndarray]:
        return self.env.render()

    def close(self) -> None:
        self.env.close()
