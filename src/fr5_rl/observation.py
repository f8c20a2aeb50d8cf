"""The observation vector: one builder shared by the environments and the ROS policy node.

It takes plain arrays (measured joint state, gripper state, tcp pose, object position, all in
``base_link``) and returns the normalised vector in [-1, 1]. The environments call it with
PyBullet's state; the policy node with ``/joint_states`` and the tf2-transformed target.

Layout (index: content, unit before normalisation, normalisation):

======  =====================================  ======  ==================================
index   content                                unit    mapped to [-1, 1] by
======  =====================================  ======  ==================================
0-5     joint positions j1..j6                 rad     FR5 lower/upper limits
6-11    joint velocities j1..j6                rad/s   FR5 velocity limits
12      gripper opening width (measured)       m       [0, max opening width]
13      gripper opening width (commanded)      m       [0, max opening width]
14-16   tcp position in base_link              m       observation.tcp_position_low/high
17-19   tcp approach axis (tcp z) in base_link unit    already in [-1, 1]
20-22   object centre minus tcp, base_link     m       / observation.relative_position_scale
23      object lift above its resting height   m       / observation.lift_scale (grasp only)
then    the policy's previous arm actions      -1..1   as given (``observation.previous_actions``
        (6 each, the newest first)                     of them; 0 = none, the default)
======  =====================================  ======  ==================================

The previous actions make latency observable. Behind a driver that applies a command one or two
periods late, the arm still has to carry out what the policy already sent, and the measured
joint state alone cannot tell a delayed arm from a slow one. They are the policy's own outputs
(arm components, clipped to [-1, 1], before smoothing and delay): what the ROS node knows it
sent, as the environment knows what the agent chose. :class:`ActionHistory` keeps them, for both.

The tcp orientation is the approach axis rather than the seed's Euler angles: with the
gripper pointing down, roll sits at +-pi and Euler angles jump there.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from collections import deque
from typing import Any, List, Mapping, Optional, Sequence

import numpy as np

from .config import RobotSpec

REACH_OBSERVATION_SIZE = 23  # without previous actions
GRASP_OBSERVATION_SIZE = 24
ARM_ACTION_SIZE = 6  # the arm components of the action (the seventh is the gripper)


def previous_action_count(obs_cfg: Mapping[str, Any]) -> int:
    """How many previous actions the observation carries (``observation.previous_actions``).

    A configuration without the key (a model trained before it existed) carries none. The
    config loader checks the value (:func:`fr5_rl.config.validate_env_config`).
    """
    return int(obs_cfg.get("previous_actions", 0))


def observation_size(task: str, obs_cfg: Mapping[str, Any]) -> int:
    """Length of the observation vector of ``task`` (``reach`` or ``grasp``) under ``obs_cfg``."""
    base = GRASP_OBSERVATION_SIZE if task == "grasp" else REACH_OBSERVATION_SIZE
    return base + ARM_ACTION_SIZE * previous_action_count(obs_cfg)


class ActionHistory:
    """The policy's last ``count`` arm actions, newest first, zeros after a reset (an episode
    starts with the arm at rest): the observation's previous-action block.

    :param count: actions kept (``observation.previous_actions``); 0 keeps none.
    """

    def __init__(self, count: int) -> None:
        self.count = int(count)
        self._actions: deque = deque(maxlen=max(self.count, 1))
        self.reset()

    def reset(self) -> None:
        """Forget every action: the block reads zeros, as at the start of an episode."""
        self._actions.clear()
        for _ in range(self.count):
            self._actions.append([0.0] * ARM_ACTION_SIZE)

    def push(self, action: Sequence[float]) -> None:
        """Record the action just sent (its first six values, clipped to [-1, 1])."""
        self._actions.appendleft([1.0 if v > 1.0 else (-1.0 if v < -1.0 else float(v))
                                  for v in action[:ARM_ACTION_SIZE]])

    def values(self) -> List[float]:
        """The block as one flat list, newest action first (``6 * count`` values)."""
        return [value for action in self._actions for value in action] if self.count else []


@dataclass
class ObservationInputs:
    """Raw, un-normalised inputs of one observation (all in ``base_link``, SI units).

    Sequences may be numpy arrays, lists or tuples.
    """

    joint_positions: Sequence[float]  # (6,) rad, controller order
    joint_velocities: Sequence[float]  # (6,) rad/s
    gripper_width: float  # m, measured pad-to-pad opening
    gripper_command_width: float  # m, last commanded opening
    tcp_position: Sequence[float]  # (3,) m
    tcp_approach_axis: Sequence[float]  # (3,) unit vector: the tcp z axis in base_link
    object_position: Sequence[float]  # (3,) m, object centre
    object_lift: float = 0.0  # m above the resting height (grasp only)
    previous_actions: Sequence[float] = ()  # ActionHistory.values(): 6 * previous_actions values


class ObservationBuilder:
    """Normalises the raw inputs into the policy's observation vector.

    The raw values are laid out in one list and mapped with a single affine transform
    ``raw * gain - bias`` (``gain = 1 / half_range``, ``bias = centre * gain``) followed by
    clipping: the layout table above, as data. The arithmetic is on plain floats: for 24
    values, right after a physics step, that measured 7-10 us faster per env step than numpy.
    :meth:`build` takes an :class:`ObservationInputs`; :meth:`build_from` takes the same
    values as arguments (the environments' step path).
    """

    def __init__(self, robot: RobotSpec, obs_cfg: Mapping[str, Any], include_lift: bool) -> None:
        self.include_lift = include_lift
        self.previous_actions = previous_action_count(obs_cfg)
        self._state_size = GRASP_OBSERVATION_SIZE if include_lift else REACH_OBSERVATION_SIZE
        self.size = self._state_size + ARM_ACTION_SIZE * self.previous_actions
        low = np.asarray(obs_cfg["tcp_position_low"], dtype=np.float64)
        high = np.asarray(obs_cfg["tcp_position_high"], dtype=np.float64)
        half_width = robot.max_opening_width / 2.0
        offset = np.zeros(GRASP_OBSERVATION_SIZE)
        half_range = np.ones(GRASP_OBSERVATION_SIZE)
        offset[0:6] = (robot.upper_limits + robot.lower_limits) / 2.0
        half_range[0:6] = (robot.upper_limits - robot.lower_limits) / 2.0
        half_range[6:12] = robot.velocity_limits
        offset[12:14], half_range[12:14] = half_width, half_width
        offset[14:17], half_range[14:17] = (high + low) / 2.0, (high - low) / 2.0
        half_range[20:23] = float(obs_cfg["relative_position_scale"])
        half_range[23] = float(obs_cfg["lift_scale"])
        gain = 1.0 / half_range[: self._state_size]
        self._gain, self._bias = gain.tolist(), (offset[: self._state_size] * gain).tolist()

    def build(self, inputs: ObservationInputs, out: Optional[np.ndarray] = None) -> np.ndarray:
        """Return the float32 observation in [-1, 1]; raises ValueError on non-finite input."""
        return self.build_from(
            inputs.joint_positions, inputs.joint_velocities, inputs.gripper_width,
            inputs.gripper_command_width, inputs.tcp_position, inputs.tcp_approach_axis,
            inputs.object_position, inputs.object_lift, inputs.previous_actions, out=out,
        )

    def build_from(self, joint_positions: Sequence[float], joint_velocities: Sequence[float],
                   gripper_width: float, gripper_command_width: float, tcp_position: Sequence[float],
                   tcp_approach_axis: Sequence[float], object_position: Sequence[float],
                   object_lift: float = 0.0, previous_actions: Sequence[float] = (),
                   out: Optional[np.ndarray] = None) -> np.ndarray:
        """The observation from the fields of :class:`ObservationInputs`, given as arguments.

        Raises ValueError on NaN or inf, on something that is not a number, or on a sequence
        of the wrong length. Finite values outside their range are clipped to [-1, 1].
        """
        try:
            lengths_ok = (len(joint_positions) == 6 and len(joint_velocities) == 6 and len(tcp_position) == 3
                          and len(tcp_approach_axis) == 3 and len(object_position) == 3
                          and len(previous_actions) == ARM_ACTION_SIZE * self.previous_actions)
        except TypeError:  # a scalar where a sequence belongs
            lengths_ok = False
        if not lengths_ok:
            raise ValueError("observation inputs need 6 joint positions, 6 velocities, 3-D tcp position, "
                             "approach axis and object position, and "
                             f"{ARM_ACTION_SIZE * self.previous_actions} previous-action values")
        try:
            tcp_x, tcp_y, tcp_z = tcp_position
            object_x, object_y, object_z = object_position
            raw = [*joint_positions, *joint_velocities, gripper_width, gripper_command_width, tcp_x, tcp_y, tcp_z,
                   *tcp_approach_axis, object_x - tcp_x, object_y - tcp_y, object_z - tcp_z]
            if self.include_lift:
                raw.append(object_lift)
            history = [float(value) for value in previous_actions] if self.previous_actions else None
            total = sum(raw) + sum(history) if history else sum(raw)
            finite = math.isfinite(total)  # a single NaN or inf makes the sum non-finite
            values = []
            if finite:
                for value, gain, bias in zip(raw, self._gain, self._bias):
                    value = value * gain - bias
                    values.append(1.0 if value > 1.0 else (-1.0 if value < -1.0 else value))
                if history:
                    values.extend(1.0 if value > 1.0 else (-1.0 if value < -1.0 else value) for value in history)
        except (TypeError, ValueError) as error:  # strings, None, arrays where numbers belong
            raise ValueError(f"observation inputs must be numbers and sequences of numbers: {error}") from None
        if not finite:
            raise ValueError("observation inputs contain NaN or inf")
        observation = np.array(values, dtype=np.float32)
        if observation.shape != (self.size,):  # e.g. (6, 1) arrays given for joint positions
            raise ValueError(f"observation inputs must be flat sequences of numbers, got shape {observation.shape}")
        if out is None:
            return observation
        out[:] = observation
        return out
