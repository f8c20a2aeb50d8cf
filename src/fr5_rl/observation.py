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
then    joint step toward the object (6)       rad     / joint_step_hint.joint_step_scale
        (``observation.joint_step_hint``;              (only when the hint is configured)
        none by default)
then    the object's shape (5): sin and cos    -1..1   as given; sizes / observation.
        of k * (its yaw - the gripper's), its  and m   object_size_scale (only with
        extent along its own x, y, z                   ``observation.object_features``)
then    the goal (4, a task with one: place):  m and   xy / relative_position_scale;
        goal minus object (x, y), sin and cos  -1..1   sin, cos as given
        of k * (the goal's yaw - the object's)
======  =====================================  ======  ==================================

The previous actions make latency observable. Behind a driver that applies a command one or two
periods late, the arm still has to carry out what the policy already sent, and the measured
joint state alone cannot tell a delayed arm from a slow one. They are the policy's own outputs
(arm components, clipped to [-1, 1], before smoothing and delay): what the ROS node knows it
sent, as the environment knows what the agent chose. :class:`ActionHistory` keeps them, for both.

The joint-step hint is the arm's inverse kinematics toward the goal, from the same measured joint
angles and object position: the joint step (damped least squares on the tcp Jacobian) that moves
the tcp straight toward the object centre and turns its approach axis toward straight down, in
action units. A policy learning from joint increments otherwise has to discover the arm's
kinematics from reward; with the hint it learns *how* to follow it (over the cup, not through it)
instead. :class:`JointStepHint` computes it, for the environments and the ROS node alike.

The tcp orientation is the approach axis rather than the seed's Euler angles: with the
gripper pointing down, roll sits at +-pi and Euler angles jump there.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from collections import deque
from typing import List, Optional, Sequence, Tuple

import numpy as np

from .config import RobotSpec, load_yaml
from .env_config import JointStepHintConfig, ObservationConfig
from .kinematics import ForwardKinematics, solve_linear as _solve
from .objects import ObjectShape, held_in_tcp

REACH_OBSERVATION_SIZE = 23  # without previous actions
GRASP_OBSERVATION_SIZE = 24
ARM_ACTION_SIZE = 6  # the arm components of the action (the seventh is the gripper)
OBJECT_FEATURE_SIZE = 5  # sin, cos of the relative yaw by symmetry; the object's three extents
GOAL_SIZE = 4  # goal minus object (x, y); sin, cos of the goal's yaw relative to the object's
# What each task's observation carries beyond the arm and the object: (the object's lift, the
# goal). The task classes (fr5_rl.tasks) declare the same as include_lift and include_goal; a
# test keeps the two equal.
TASK_BLOCKS = {"reach": (False, False), "grasp": (True, False), "place": (True, True)}


def observation_size(task: str, obs_cfg: ObservationConfig) -> int:
    """Length of the observation vector of ``task`` (:data:`TASK_BLOCKS`) under ``obs_cfg``."""
    include_lift, include_goal = TASK_BLOCKS[task]
    base = GRASP_OBSERVATION_SIZE if include_lift else REACH_OBSERVATION_SIZE
    hint = ARM_ACTION_SIZE if obs_cfg.joint_step_hint is not None else 0
    shape = OBJECT_FEATURE_SIZE if obs_cfg.object_features else 0
    return base + ARM_ACTION_SIZE * obs_cfg.previous_actions + hint + shape + (GOAL_SIZE if include_goal else 0)


def goal_features(shape: ObjectShape, object_position: Sequence[float], object_yaw: float,
                  goal: Sequence[float]) -> List[float]:
    """The raw goal block: goal minus object (x, y, m, base_link), then ``(sin kΔ, cos kΔ)`` of the
    goal's yaw relative to the object's (``(0, 0)`` for a cylinder).

    :param object_yaw: rad, the object's x axis in base_link (:func:`~fr5_rl.objects.yaw_of`).
    :param goal: (x, y, yaw) of where the object is to stand (m, m, rad; base_link).
    """
    sine, cosine = shape.yaw_features(goal[2], object_yaw)
    return [goal[0] - object_position[0], goal[1] - object_position[1], sine, cosine]


def object_features(shape: ObjectShape, object_yaw: float, gripper_yaw: float) -> List[float]:
    """The raw object block of the observation: ``(sin kΔ, cos kΔ)`` of the object's yaw relative
    to the gripper's (:meth:`ObjectShape.yaw_features`), then its extent along its own x, y, z (m).

    :param object_yaw: rad, the object's x axis in base_link (:func:`~fr5_rl.objects.yaw_of`).
    :param gripper_yaw: rad, the tcp frame's x axis in base_link.
    """
    sine, cosine = shape.yaw_features(object_yaw, gripper_yaw)
    return [sine, cosine, *shape.size]


class JointStepHint:
    """The joint step, in action units, that moves the tcp toward the object centre and turns its
    approach axis toward straight down (base_link -z): damped least squares on the tcp Jacobian,
    ``dq = J^T (J J^T + damping^2 I)^-1 e``.

    The Cartesian error ``e`` is capped per step, so far from the object the hint is a direction
    at a steady speed, and near it the remaining offset.

    :param robot: the arm's kinematics.
    :param settings: ``observation.joint_step_hint``: ``cartesian_step`` (m) and
        ``rotation_step`` (rad), the most the tcp is asked to move and turn in one step;
        ``damping`` (m), which keeps the step small near singular poses; ``joint_step_scale``
        (rad), the step read as 1 (``action.max_joint_step``: the hint then reads as an action).
    """

    def __init__(self, robot: RobotSpec, settings: JointStepHintConfig) -> None:
        self._kinematics = ForwardKinematics(robot)
        self._cartesian_step = settings.cartesian_step
        self._rotation_step = settings.rotation_step
        self._damping = settings.damping ** 2 * np.eye(6)
        self._gain = 1.0 / settings.joint_step_scale

    def __call__(self, joint_positions: Sequence[float], object_position: Sequence[float],
                 tcp_jacobian: Optional[Tuple[List[float], List[float], List[List[float]]]] = None) -> List[float]:
        """Six values in [-1, 1]: the hinted step of j1..j6 / ``joint_step_scale``.

        :param joint_positions: j1..j6 (rad), finite.
        :param object_position: object centre (m, base_link), finite.
        :param tcp_jacobian: :meth:`ForwardKinematics.tcp_jacobian` of ``joint_positions``, where
            the caller has it already (the noisy observation's tcp pose needs the same chain);
            None: computed here.
        """
        if tcp_jacobian is None:
            tcp_jacobian = self._kinematics.tcp_jacobian(joint_positions)
        (tcp_x, tcp_y, tcp_z), (axis_x, axis_y, axis_z), jacobian = tcp_jacobian
        object_x, object_y, object_z = object_position
        dx, dy, dz = object_x - tcp_x, object_y - tcp_y, object_z - tcp_z
        distance = math.sqrt(dx * dx + dy * dy + dz * dz)
        if distance > self._cartesian_step:
            shrink = self._cartesian_step / distance
            dx, dy, dz = dx * shrink, dy * shrink, dz * shrink
        # Rotation that takes the approach axis toward -z: axis x (0, 0, -1), |.| = sin(angle).
        wx, wy = -axis_y, axis_x
        turn = math.sqrt(wx * wx + wy * wy)
        if turn > self._rotation_step:
            wx, wy = wx * self._rotation_step / turn, wy * self._rotation_step / turn
        jacobian = np.array(jacobian)
        weights = _solve(jacobian @ jacobian.T + self._damping, np.array((dx, dy, dz, wx, wy, 0.0)))
        gain = self._gain
        return [1.0 if value > 1.0 else (-1.0 if value < -1.0 else value)
                for value in (jacobian.T @ weights * gain).tolist()]


# Two samples closer than this (s) are one sample twice (a repeated message): no new estimate.
MIN_SAMPLE_INTERVAL = 1e-4


def velocity_from_positions(position: float, previous_position: float, elapsed: float,
                            previous_velocity: float) -> float:
    """A joint's velocity (rad/s) from two position samples ``elapsed`` s apart: what a driver
    that reports none leaves the policy (the FAIRINO driver's velocities are all 0.0). The policy
    node's :class:`~fr5_rl.deploy.joint_state.JointStateReader` and the environments
    (``observation.joint_velocity_source: positions``) both estimate with this, from the samples
    they get (50 Hz behind the FAIRINO driver, one a control period in the environment).

    :param previous_velocity: the estimate to keep when the samples are one (``elapsed`` under
        :data:`MIN_SAMPLE_INTERVAL`).
    """
    if elapsed < MIN_SAMPLE_INTERVAL:
        return previous_velocity
    return (position - previous_position) / elapsed


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
    object_features: Sequence[float] = ()  # object_features(): 5 values with observation.object_features
    goal: Sequence[float] = ()  # goal_features(): 4 values for a task with a goal


class ObservationBuilder:
    """Normalises the raw inputs into the policy's observation vector.

    The raw values are laid out in one list and mapped with a single affine transform
    ``raw * gain - bias`` (``gain = 1 / half_range``, ``bias = centre * gain``) followed by
    clipping: the layout table above, as data. The arithmetic is on plain floats: for 24
    values, right after a physics step, that measured 7-10 us faster per env step than numpy.
    :meth:`build` takes an :class:`ObservationInputs`; :meth:`build_from` takes the same
    values as arguments (the environments' step path).
    """

    def __init__(self, robot: RobotSpec, obs_cfg: ObservationConfig, include_lift: bool,
                 include_goal: bool = False) -> None:
        self.include_lift, self.include_goal = include_lift, include_goal
        self.previous_actions = obs_cfg.previous_actions
        self._state_size = GRASP_OBSERVATION_SIZE if include_lift else REACH_OBSERVATION_SIZE
        self.size = self._state_size + ARM_ACTION_SIZE * self.previous_actions
        hint = obs_cfg.joint_step_hint
        self.joint_step_hint: Optional[JointStepHint] = None if hint is None else JointStepHint(robot, hint)
        if self.joint_step_hint is not None:
            self.size += ARM_ACTION_SIZE
        self.object_features = obs_cfg.object_features
        self._object_size_gain = 1.0 / obs_cfg.object_size_scale
        if self.object_features:
            self.size += OBJECT_FEATURE_SIZE
        self._goal_gain = 1.0 / obs_cfg.relative_position_scale
        if include_goal:
            self.size += GOAL_SIZE
        low = np.asarray(obs_cfg.tcp_position_low, dtype=np.float64)
        high = np.asarray(obs_cfg.tcp_position_high, dtype=np.float64)
        half_width = robot.max_opening_width / 2.0
        offset = np.zeros(GRASP_OBSERVATION_SIZE)
        half_range = np.ones(GRASP_OBSERVATION_SIZE)
        offset[0:6] = (robot.upper_limits + robot.lower_limits) / 2.0
        half_range[0:6] = (robot.upper_limits - robot.lower_limits) / 2.0
        half_range[6:12] = robot.velocity_limits
        offset[12:14], half_range[12:14] = half_width, half_width
        offset[14:17], half_range[14:17] = (high + low) / 2.0, (high - low) / 2.0
        half_range[20:23] = obs_cfg.relative_position_scale
        half_range[23] = obs_cfg.lift_scale
        gain = 1.0 / half_range[: self._state_size]
        self._gain, self._bias = gain.tolist(), (offset[: self._state_size] * gain).tolist()

    def build(self, inputs: ObservationInputs, out: Optional[np.ndarray] = None) -> np.ndarray:
        """Return the float32 observation in [-1, 1]; raises ValueError on non-finite input."""
        return self.build_from(
            inputs.joint_positions, inputs.joint_velocities, inputs.gripper_width,
            inputs.gripper_command_width, inputs.tcp_position, inputs.tcp_approach_axis,
            inputs.object_position, inputs.object_lift, inputs.previous_actions, out=out,
            object_features=inputs.object_features, goal=inputs.goal,
        )

    def build_from(self, joint_positions: Sequence[float], joint_velocities: Sequence[float],
                   gripper_width: float, gripper_command_width: float, tcp_position: Sequence[float],
                   tcp_approach_axis: Sequence[float], object_position: Sequence[float],
                   object_lift: float = 0.0, previous_actions: Sequence[float] = (),
                   out: Optional[np.ndarray] = None,
                   tcp_jacobian: Optional[Tuple[List[float], List[float], List[List[float]]]] = None,
                   object_features: Sequence[float] = (), goal: Sequence[float] = ()) -> np.ndarray:
        """The observation from the fields of :class:`ObservationInputs`, given as arguments.

        ``tcp_jacobian``: the joint-step hint's kinematics of ``joint_positions``
        (:meth:`ForwardKinematics.tcp_jacobian`) where the caller computed them already.
        ``object_features``: :func:`object_features` of the object, with
        ``observation.object_features`` (else empty). ``goal``: :func:`goal_features`, for a task
        with a goal (else empty).

        Raises ValueError on NaN or inf, on something that is not a number, or on a sequence
        of the wrong length. Finite values outside their range are clipped to [-1, 1].
        """
        try:
            lengths_ok = (len(joint_positions) == 6 and len(joint_velocities) == 6 and len(tcp_position) == 3
                          and len(tcp_approach_axis) == 3 and len(object_position) == 3
                          and len(previous_actions) == ARM_ACTION_SIZE * self.previous_actions
                          and len(object_features) == (OBJECT_FEATURE_SIZE if self.object_features else 0)
                          and len(goal) == (GOAL_SIZE if self.include_goal else 0))
        except TypeError:  # a scalar where a sequence belongs
            lengths_ok = False
        if not lengths_ok:
            raise ValueError("observation inputs need 6 joint positions, 6 velocities, 3-D tcp position, "
                             "approach axis and object position, "
                             f"{ARM_ACTION_SIZE * self.previous_actions} previous-action values and "
                             f"{OBJECT_FEATURE_SIZE if self.object_features else 0} object-shape values and "
                             f"{GOAL_SIZE if self.include_goal else 0} goal values")
        try:
            tcp_x, tcp_y, tcp_z = tcp_position
            object_x, object_y, object_z = object_position
            raw = [*joint_positions, *joint_velocities, gripper_width, gripper_command_width, tcp_x, tcp_y, tcp_z,
                   *tcp_approach_axis, object_x - tcp_x, object_y - tcp_y, object_z - tcp_z]
            if self.include_lift:
                raw.append(object_lift)
            history = [float(value) for value in previous_actions] if self.previous_actions else None
            total = sum(raw) + sum(history) if history else sum(raw)
            if self.object_features:
                total += sum(float(value) for value in object_features)
            if self.include_goal:
                total += sum(float(value) for value in goal)
            finite = math.isfinite(total)  # a single NaN or inf makes the sum non-finite
            values = []
            if finite:
                for value, gain, bias in zip(raw, self._gain, self._bias):
                    value = value * gain - bias
                    values.append(1.0 if value > 1.0 else (-1.0 if value < -1.0 else value))
                if history:
                    values.extend(1.0 if value > 1.0 else (-1.0 if value < -1.0 else value) for value in history)
                if self.joint_step_hint is not None:
                    values.extend(self.joint_step_hint(joint_positions, object_position, tcp_jacobian))
                if self.object_features:
                    sine, cosine, *extents = (float(value) for value in object_features)
                    values.extend((sine, cosine))
                    gain = self._object_size_gain
                    values.extend(min(value * gain, 1.0) for value in extents)
                if self.include_goal:
                    goal_x, goal_y, sine, cosine = (float(value) for value in goal)
                    gain = self._goal_gain
                    values.extend(1.0 if value > 1.0 else (-1.0 if value < -1.0 else value)
                                  for value in (goal_x * gain, goal_y * gain))
                    values.extend((sine, cosine))
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


@functools.lru_cache(maxsize=1)
def tracker_closing_axis() -> Tuple[float, ...]:
    """The detector's tracker's finger closing axis (tcp frame, config/detector.yaml), read once:
    a camera target is built at every episode's reset."""
    return tuple(float(v) for v in load_yaml("detector")["tracker"]["closing_axis"])


def tracker_hidden_timeout() -> Optional[float]:
    """The detector's tracker's ``hidden_timeout`` (s, config/detector.yaml): how long a hidden
    object is still believed where it was last seen; None where the file switches tracking off (0)."""
    value = float(load_yaml("detector")["tracker"]["hidden_timeout"])
    return value if value > 0.0 else None


class DelayedTarget:
    """The object's position (and yaw, appended to it) as a camera and the detector deliver it
    (``randomisation.target_share``).

    Frames are captured every ``frame_period`` from ``phase`` on; each reaches the policy
    ``latency`` after its capture and stands until the next one arrives. Before the first frame
    arrives the scene at the episode's start is seen (the simulator holds a new scene until a
    frame of it is through). Once the object is in the hand the detector's tracker publishes it
    in the tcp frame, so it is seen without delay. A frame captured while the hand hides the
    object shows where it was last seen, in a frame or in the hand (the tracker's hold; once let
    go, standing on the table below where the hand left it, as the tracker puts it): the
    target does not follow a push (the tracker's search for a hidden object nudged up to
    ``nudge_radius``, which keeps its track, is not modelled).

    With ``hand_from_grasp`` the held object is not seen at its true position but where the
    tracker puts it (:meth:`fr5_rl.perception.tracker.ObjectTracker._take_into_hand`): fixed in
    the tcp frame as it was last seen relative to the lowest tcp pose with the fingers around it,
    centred along ``closing_axis``. A grip that slid, or an object nudged while hidden, is then
    seen 5-10 mm off, as through the rehearsal; its yaw stays the true one (the pads square it).

    :param latency: s from capture to the policy node.
    :param frame_period: s between two frames (1 / the camera's rate).
    :param phase: s of the first capture after the episode's start (0 … frame_period).
    :param hand_from_grasp: the held object as the tracker computes it (see above).
    :param closing_axis: the direction (tcp frame) the fingers close along; None: the tracker's
        own (config/detector.yaml ``tracker.closing_axis``).
    :param hidden_timeout: s after its last sighting (in a frame, or in the hand) that a hidden
        object is dropped, as the tracker drops it (config/detector.yaml ``tracker.hidden_timeout``):
        nothing new is published until a frame shows it again, so :attr:`seen_at` stops advancing
        and the policy node finds its target stale. None: never (the training world's policy acts
        on every period).
    """

    def __init__(self, latency: float, frame_period: float, phase: float, hand_from_grasp: bool = False,
                 closing_axis: Optional[Sequence[float]] = None, hidden_timeout: Optional[float] = None) -> None:
        self.latency, self.frame_period, self.phase = latency, frame_period, phase
        self.history: deque = deque()  # (time s, position, hidden) of every period, oldest first
        self._last_seen: Optional[Sequence[float]] = None  # the newest position seen, in a frame or in the hand
        self.seen_at = 0.0  # s since the episode's start: when what observe() returned was captured
        self.hand_from_grasp = hand_from_grasp
        if hand_from_grasp and closing_axis is None:
            closing_axis = tracker_closing_axis()
        self._closing_axis = None if closing_axis is None else tuple(closing_axis)
        self._grasp_low: Optional[Tuple[np.ndarray, np.ndarray]] = None  # tcp (position, rotation), lowest around it
        self._in_tcp: Optional[np.ndarray] = None  # the held object's centre in the tcp frame (m)
        self._in_hand = False  # the last observation had it in the hand
        self._rest_z: Optional[float] = None  # m, its centre's height standing on the table
        self.hidden_timeout = hidden_timeout
        self._sighted_at = 0.0  # s: the capture of the last frame that showed it, or the last period in the hand

    def observe(self, position: Sequence[float], now: float, in_hand: bool, hidden: bool = False,
                tcp: Optional[Tuple[np.ndarray, np.ndarray]] = None, around: bool = False) -> Sequence[float]:
        """The position the policy sees at ``now`` (s since the episode's start).

        :param position: the object's true position now (m, base_link), and its yaw (rad) after
            it where the observation has one: held with it.
        :param in_hand: the object is held by the fingers (seen without delay).
        :param hidden: the hand hides the object from the camera now (a frame captured now
            shows where it was last seen).
        :param tcp: the tcp's position (m, base_link) and rotation (3x3) now; needed with
            ``hand_from_grasp`` (None: the true position while held).
        :param around: the fingers are around the object (closed to a width that holds it, the
            tcp near it), held or not.
        """
        self.history.append((now, position, hidden))
        if self._rest_z is None:
            self._rest_z = float(position[2])  # it starts standing on the table
        # Once taken, the tracker keeps it in the hand until the fingers open, set down or not.
        if in_hand or (self._in_tcp is not None and around and tcp is not None):
            if self.hand_from_grasp and tcp is not None:
                position = self._as_the_tracker_holds(position, tcp)
            self._last_seen, self.seen_at = position, now
            self._sighted_at = now
            self._in_hand = True
            return position
        if self._in_hand and self._last_seen is not None:
            # Let go: the tracker puts it on the table below where the hand left it
            # (ObjectTracker._follow_hand). Kept in the air where the hand had it, a policy that
            # dropped an object 15 mm up came back for it there and pressed the palm onto its top.
            self._last_seen = (*self._last_seen[:2], self._rest_z, *self._last_seen[3:])
        self._in_hand = False
        self._in_tcp = None
        if self.hand_from_grasp:
            if not around or tcp is None:
                self._grasp_low = None
            elif self._grasp_low is None or tcp[0][2] < self._grasp_low[0][2]:
                self._grasp_low = tcp
        newest_capture = now - self.latency
        if newest_capture < self.phase:
            self.seen_at = self.history[0][0]
            return self.history[0][1]
        capture = self.phase + math.floor((newest_capture - self.phase) / self.frame_period + 1e-9) * self.frame_period
        # The position at the capture: the last period sampled at or before it.
        while len(self.history) > 1 and self.history[1][0] <= capture + 1e-9:
            self.history.popleft()
        _, captured, captured_hidden = self.history[0]
        if captured_hidden and self._last_seen is not None:
            if self.hidden_timeout is None or capture - self._sighted_at <= self.hidden_timeout:
                self.seen_at = capture  # the tracker's hold: published with each frame
            return self._last_seen
        self._last_seen, self.seen_at, self._sighted_at = captured, capture, capture
        return captured

    @property
    def held_in_tcp(self) -> Optional[np.ndarray]:
        """The held object's centre in the tcp frame (m) as the tracker fixed it when it took the
        object, while held with ``hand_from_grasp``; else None."""
        return self._in_tcp

    def _as_the_tracker_holds(self, position: Sequence[float], tcp: Tuple[np.ndarray, np.ndarray]) -> Sequence[float]:
        """The held object's position (and the true yaw after it) as the tracker computes it."""
        tcp_position, tcp_rotation = tcp
        if self._in_tcp is None:
            seen = self._last_seen if self._last_seen is not None else position
            low_position, low_rotation = self._grasp_low if self._grasp_low is not None else tcp
            self._in_tcp = held_in_tcp(low_position, low_rotation, seen, self._closing_axis)
            self._grasp_low = None  # taken: a later grasp (after a set-down) has its own lowest pose
        held_at = tcp_position + tcp_rotation @ self._in_tcp
        return (float(held_at[0]), float(held_at[1]), float(held_at[2]), *position[3:])
