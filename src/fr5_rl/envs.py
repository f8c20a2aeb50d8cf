"""Gymnasium environments FR5Reach-v0 and FR5Grasp-v0: an :class:`~fr5_rl.episode.Episode` in gymnasium's API.

One ``step`` is one 50 Hz control period: the action goes through the control chain
(:mod:`fr5_rl.control_chain`: the same :class:`~fr5_rl.control.JointCommandShaper` the ROS
policy node uses, and the real chain's timing as drawn), the plant (:mod:`fr5_rl.sim.plant`)
tracks it for ``control_dt`` seconds, the task judges it, and the observation is built by the
same :class:`~fr5_rl.observation.ObservationBuilder` the ROS node runs. Only :mod:`fr5_rl.sim`
talks to PyBullet.
"""
from __future__ import annotations

import dataclasses
import os
from typing import Any, Dict, Mapping, Optional, Tuple, Union

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.envs.registration import EnvSpec

from .config import load_robot_spec
from .control import ACTION_SIZE, finite_values
from .env_config import EnvConfig, load_env_config
from .episode import Episode
from .objects import ObjectShape
from .tasks import TASKS, TaskState

_REWARD_KEYS = {name: f"reward_{name}" for name in ("success", "collision", "failure", "progress", "action")}
_TERM_KEYS = {name: f"term_{name}" for name in ("approach", "orientation", "gripper", "lift", "carry", "yaw",
                                                 "release")}


class FR5Env(gym.Env):
    """An arm of the family + gripper in PyBullet. Observation and action layouts: see
    fr5_rl.observation and fr5_rl.control. ``info`` carries ``is_success``, ``failure`` and every
    reward part.

    :param task: a task's name (:data:`fr5_rl.tasks.TASKS`: ``reach``, ``grasp``).
    :param config: overrides merged into ``config/env.yaml`` (unknown keys are refused), or an
        :class:`~fr5_rl.env_config.EnvConfig` already loaded.
    :param render_mode: None, "rgb_array" (headless TinyRenderer) or "human" (PyBullet GUI).
    :param robot: the arm (``fr5``, ``fr10``, …: ``config/robots/``), the same as
        ``config={"robot": …}``; None: the config's (``fr5`` by default).
    """

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 50}
    _spec: Optional[EnvSpec] = None

    def __init__(self, task: str = "reach", config: Union[EnvConfig, Mapping[str, Any], None] = None,
                 render_mode: Optional[str] = None, robot: Optional[str] = None) -> None:
        super().__init__()
        if task not in TASKS:
            raise ValueError(f"unknown task '{task}'; choose one of {sorted(TASKS)}")
        if render_mode not in (None, "rgb_array", "human"):
            raise ValueError(f"render_mode must be None, 'rgb_array' or 'human', got {render_mode!r}")
        # What this machine can render: without an X display no "human" window (gymnasium's
        # check_env tries every mode listed here).
        self.metadata = {**self.metadata, "render_modes": ["rgb_array"] + (["human"] if os.environ.get("DISPLAY") else [])}
        if isinstance(config, EnvConfig):
            if robot is not None and robot != config.robot:
                raise ValueError(f"robot='{robot}' contradicts the configuration's robot '{config.robot}'")
            self.cfg = config
        else:
            self.cfg = load_env_config({**(config or {}), **({"robot": robot} if robot is not None else {})})
        self.robot_spec = load_robot_spec(self.cfg.robot)
        self.render_mode = render_mode
        self.episode = Episode(task, self.cfg, self.robot_spec, gui=render_mode == "human",
                               renders=render_mode is not None)
        self.control_dt = self.episode.control_dt
        self.task, self.plant, self.kinematics = self.episode.task, self.episode.plant, self.episode.kinematics
        self.observation_space = spaces.Box(-1.0, 1.0, (self.episode.observation_builder.size,), dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, (ACTION_SIZE,), dtype=np.float32)

    @property
    def spec(self) -> Optional[EnvSpec]:
        """gymnasium's spec, with ``max_episode_steps`` the configured task's ``max_steps``: the
        environment truncates itself there (a TimeLimit fixed at registration would cut an
        episode the configuration makes longer)."""
        return self._spec

    @spec.setter
    def spec(self, value: Optional[EnvSpec]) -> None:
        if value is not None and value.max_episode_steps is None and hasattr(self, "cfg"):
            value = dataclasses.replace(value, max_episode_steps=self.cfg.task(self.task.name).max_steps)
        self._spec = value

    # ------------------------------------------------------------------ gym API
    def reset(self, *, seed: Optional[int] = None, options: Optional[Dict[str, Any]] = None
              ) -> Tuple[np.ndarray, Dict[str, Any]]:
        """A new episode. ``options``: ``object_xy`` (m, base_link) places the object there;
        ``arm_positions`` (rad, j1..j6) keeps the arm there instead of a start drawn around home
        (the random draws are made either way, so a seed places the same object)."""
        super().reset(seed=seed)
        _, observation = self.episode.reset(self.np_random, options)
        return observation, {"is_success": False, "failure": None, "object_start": np.array(self.episode.object_start)}

    def step(self, action: np.ndarray) -> Tuple[np.ndarray, float, bool, bool, Dict[str, Any]]:
        # Plain floats from here on: for seven values that is faster than numpy, and this runs
        # thousands of times a second.
        values = finite_values(action, ACTION_SIZE, "the action")
        values = [1.0 if value > 1.0 else (-1.0 if value < -1.0 else value) for value in values]
        state, observation = self.episode.act(values, self.np_random)
        verdict = self.episode.judge_period(state)
        parts = self.task.reward(verdict.outcome, values)
        info: Dict[str, Any] = {"is_success": verdict.success, "failure": verdict.failure}
        for name, value in parts.items():
            info[_REWARD_KEYS[name]] = value
        for name, value in verdict.outcome.terms.items():
            info[_TERM_KEYS[name]] = value
        if self.render_mode == "human":
            self.render()
        return observation, sum(parts.values()), verdict.terminated, verdict.truncated, info

    def render(self) -> Optional[np.ndarray]:
        return self.plant.render() if self.render_mode == "rgb_array" else None

    def close(self) -> None:
        self.episode.close()

    # ------------------------------------------------------------------ saved states
    def save_state(self) -> Dict[str, Any]:
        """The episode as it stands, to go on from later with :meth:`restore_state`: the
        simulator's state and everything a step changes (the chain's queues and filters, the
        task's timers and potential, the step count, ...).

        Restoring is only meaningful in the same episode's world (no :meth:`reset` in between:
        a reset builds a new object). The random stream is not saved: after a restore the episode
        goes on with fresh draws (in a plain configuration steps draw nothing, and a restored
        episode goes on exactly as the saved one did). A saved state holds simulator memory until
        :meth:`discard_state`.
        """
        return self.episode.save_state()

    def restore_state(self, saved: Dict[str, Any]) -> None:
        """Go back to a state from :meth:`save_state` (it stays saved: restore it again or discard it)."""
        self.episode.restore_state(saved)

    def discard_state(self, saved: Dict[str, Any]) -> None:
        """Free the simulator memory of a state from :meth:`save_state`."""
        self.episode.discard_state(saved)

    # ------------------------------------------------------------------ inspection
    def task_state(self) -> TaskState:
        """Ground-truth state the task judges (also read by the scripted expert)."""
        return self.episode.task_state()

    def tcp_position(self) -> np.ndarray:
        """tcp position in the world (= base_link) frame, metres, from the simulator."""
        return self.plant.tcp_position()

    def object_position(self) -> np.ndarray:
        """Object centre in the world (= base_link) frame, metres."""
        return np.array(self.plant.object_pose().position)

    def object_description(self) -> ObjectShape:
        """This episode's object: its kind and size (m)."""
        return self.episode.scene().object_description

    def joint_positions(self) -> np.ndarray:
        """Measured arm joint angles (rad), controller order."""
        return self.plant.joint_positions()

    @property
    def object_rest_z(self) -> float:
        """z (m, base_link) of the object's centre when it stands on the table."""
        return self.plant.object_rest_z
