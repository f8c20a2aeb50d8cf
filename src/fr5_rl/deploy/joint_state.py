"""Reading a sensor_msgs/JointState-like message by joint name (no ROS import needed).

``/joint_states`` carries no order guarantee and may hold other joints too: every value is
looked up by name, and anything missing, mis-sized or non-finite is rejected with a reason.
"""
from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import Dict, Generic, List, Optional, Sequence, Set, Tuple, TypeVar

import numpy as np

from ..observation import MIN_SAMPLE_INTERVAL, velocity_from_positions

T = TypeVar("T")


@dataclass(frozen=True)
class Reading(Generic[T]):
    """The newest value of one input, or why it is unusable, with its arrival time.

    :param value: the value; None when ``problem`` is set.
    :param received: arrival time (s) on the caller's monotonic clock.
    :param problem: why the input is unusable (a parse or tf failure), else None.
    :param stamp: the message's header stamp (s, ROS time); 0 when it carries none.
    """

    value: Optional[T]
    received: float
    problem: Optional[str] = None
    stamp: float = 0.0


@dataclass
class ArmJointState:
    """Arm state in controller order (rad, rad/s); gripper opening width (m) if reported."""

    positions: np.ndarray
    velocities: Optional[np.ndarray]
    gripper_width: Optional[float]


def velocities_from_positions(driver_source: str, trained_source: str) -> bool:
    """Whether the node estimates joint velocities from positions rather than take the driver's.

    :param driver_source: what the driver sends (the node's ``~joint_velocity_source``): ``driver``
        (true velocities) or ``positions`` (none, or all 0.0, as the FAIRINO driver).
    :param trained_source: what the policy observed in training (``observation.joint_velocity_source``
        of its meta.json): ``measured`` or ``positions``.
    :return: True when either says so: a policy trained on estimated velocities gets the same
        estimate behind a driver that sends true ones, since the two differ by the estimate's lag.
    """
    return driver_source == "positions" or trained_source == "positions"


class FreshStateWait:
    """Which joint state the last control period acted on, so that the next acts on a newer one.

    A driver that publishes at the control rate (the FAIRINO driver: 50 Hz) runs on its own
    clock, not the node's timer. Where its states arrive close to the timer's ticks, delivery
    jitter hands some periods the state the period before used: through ROS about one period in
    ten. Such a period adds its increment to a position a whole period old, so the arm makes
    less of each step than in training, and the repeats come and go with a phase drawn at each
    start. A period that finds no new state waits for one, up to ``wait_s``; the node's periods
    then follow the driver's states, however the two clocks lie.

    A new state is not enough either: the phase between the driver's clock and the timer, drawn
    at each start, sets how old the newest state is at a tick (0-20 ms at 50 Hz), and behind the
    emulated FAIRINO driver the place model did 10/20 with states 0 ms old and 0/20 (12 knocked
    over) with states 12 ms old; with this wait, 10/20 at 12 ms (docs/experiments.md, stops 61-62). With ``max_age_s`` a state that arrived longer ago
    than that is waited past too, so every period starts just after the driver's state, whatever
    the phase: the node's periods lock onto the driver's.

    :param wait_s: the longest a period waits for a new state (s); 0: never.
    :param max_age_s: a state that arrived longer ago than this (s) is waited past as well, within
        ``wait_s``; 0: any age will do.
    """

    def __init__(self, wait_s: float, max_age_s: float = 0.0) -> None:
        if not wait_s >= 0.0:
            raise ValueError(f"the wait for a new joint state must be >= 0 s, got {wait_s}")
        if not max_age_s >= 0.0:
            raise ValueError(f"the largest age of a fresh joint state must be >= 0 s, got {max_age_s}")
        self.wait_s = float(wait_s)
        self.max_age_s = float(max_age_s)
        self._used: Optional[Tuple[float, float]] = None

    @staticmethod
    def _key(reading: Optional[Reading]) -> Optional[Tuple[float, float]]:
        return None if reading is None or reading.value is None else (reading.received, reading.stamp)

    def is_new(self, reading: Optional[Reading], now: Optional[float] = None) -> bool:
        """Whether ``reading`` is a state no period acted on and, given ``now`` (s, the clock of
        its ``received``) and a ``max_age_s``, arrived within it (an unusable one counts as new:
        the period holds on it at once, it has nothing to wait for)."""
        key = self._key(reading)
        if key is None:
            return True
        if key == self._used:
            return False
        return now is None or self.max_age_s <= 0.0 or now - reading.received <= self.max_age_s

    def used(self, reading: Optional[Reading]) -> None:
        """A period acted on ``reading``."""
        key = self._key(reading)
        if key is not None:
            self._used = key


class JointStateReader:
    """Merges joint-state messages *by name* into the newest :class:`ArmJointState`.

    ``/joint_states`` may come from several publishers (the arm's driver, a gripper driver),
    each with some joints, in any order. Every joint keeps its newest value and when it came;
    a reading's ``received`` is the arrival of its *oldest* arm joint, so one silent joint makes
    the whole state stale. A message that names a joint twice, or holds NaN or inf, or whose
    arrays do not match its names, is refused as a whole and holds the arm until a good message
    brings the joints it was about. Velocities a driver leaves out, or all of them with
    ``velocities_from_positions`` (a driver whose velocities are not measured: the FAIRINO
    driver's are all 0.0), are estimated per joint from positions and stamps, with the same
    :func:`~fr5_rl.observation.velocity_from_positions` the environments use, over at least
    ``estimate_interval``: a driver publishing faster than the environment samples (a 200 Hz
    simulator against one sample a control period) would otherwise divide a message's jitter by
    5 ms instead of 20. A message
    whose arm positions imply a speed above ``max_joint_speeds`` from the last state the reader
    trusted (an encoder or driver fault) latches a hold: it clears only when every arm joint
    reads back within ``max_joint_speeds`` x ``recovery_window`` of that trusted state, in a
    message that agrees with the one before it (a one-message spike), or when an operator vouches for the state as it stands
    (:meth:`accept_current`, the policy node's ``~enable``). A reading that jumps and stays is
    as much a fault as one that jumps back: commanding from it would move the arm by the jump.
    Thread-safe: ROS callbacks update, the timer reads.

    :param arm_joint_names: the arm's joints in controller order (``j1`` … ``j6``).
    :param finger_joint_names: the gripper's finger joints (their sum is the opening width).
    :param velocities_from_positions: ignore the messages' velocities and estimate them.
    :param max_joint_speeds: rad/s per arm joint (controller order) that no real motion exceeds;
        None: no check.
    :param estimate_interval: s an estimate spans at least (the sample before that is kept):
        most of the control period the policy was trained at; 0 takes consecutive messages.
    :param recovery_window: s the arm can have gone on moving after a jump made the node hold
        (on its last command); bounds how far from the trusted state a reading may come back.
    """

    def __init__(self, arm_joint_names: Sequence[str], finger_joint_names: Sequence[str],
                 velocities_from_positions: bool = False, max_joint_speeds: Optional[Sequence[float]] = None,
                 estimate_interval: float = 0.0, recovery_window: float = 0.04) -> None:
        self.arm_joint_names = tuple(arm_joint_names)
        self.finger_joint_names = tuple(finger_joint_names)
        self._known = set(self.arm_joint_names) | set(self.finger_joint_names)
        self._velocities_from_positions = velocities_from_positions
        self._max_speed = (dict(zip(self.arm_joint_names, (float(v) for v in max_joint_speeds)))
                           if max_joint_speeds is not None else {})
        self._recovery_window = float(recovery_window)
        # name -> (position rad, header stamp s): the newest arm state that passed the speed check
        self._trusted: Dict[str, Tuple[float, float]] = {}
        self._latch: Optional[Tuple[str, float]] = None  # why, and when it came
        self._off: Set[str] = set()  # latched: the joints not yet back near their trusted positions
        # name -> (position rad|m, velocity, stamp or arrival s (for velocity estimates), received s,
        # header stamp s or 0)
        self._joints: Dict[str, Tuple[float, float, float, float, float]] = {}
        self._problem: Optional[Tuple[str, float, frozenset]] = None  # text, received, joints it was about
        self._restarted: Set[str] = set()  # joints whose next estimate starts from 0.0 (a new episode)
        self._estimate_interval = float(estimate_interval)
        # name -> (position, stamp): the sample an estimate is taken against, at least
        # estimate_interval before the newest (the newest one older than that).
        self._reference: Dict[str, Tuple[float, float]] = {}
        self._candidates: Dict[str, List[Tuple[float, float]]] = {}
        self._lock = threading.Lock()

    def update(self, names: Sequence[str], positions: Sequence[float], velocities: Sequence[float],
               stamp: float, received: float) -> Optional[str]:
        """Take one message; returns what is wrong with it, or None.

        :param stamp: the message's header stamp (s); 0 when the driver leaves it empty.
        :param received: arrival time (s) on the caller's monotonic clock.
        """
        problem = self._check(names, positions, velocities)
        with self._lock:
            if problem is not None:
                about = frozenset(name for name in names if name in self._known) or frozenset(self.arm_joint_names)
                self._problem = (problem, received, about)
                return problem
            header_stamp, stamp = stamp, stamp or received
            jump, checked = None, {}
            for index, name in enumerate(names):
                if name not in self._known:
                    continue  # other joints on the topic are none of the policy's business
                position = float(positions[index])
                previous = self._joints.get(name)
                # Judged on header stamps only: arrival times bunch up behind a busy network.
                if name in self._max_speed and header_stamp > 0.0:
                    checked[name] = position
                    trusted = self._trusted.get(name)
                    if trusted is not None and self._latch is None and jump is None:
                        jump = self._implausible(name, position - trusted[0], header_stamp - trusted[1])
                    elif trusted is not None and self._latch is not None:
                        # Back where the arm can be, and agreeing with the message before (a driver
                        # glitching every other message stays held).
                        bound = self._max_speed[name] * min(max(header_stamp - trusted[1], 0.0), self._recovery_window)
                        back = abs(position - trusted[0]) <= bound + 1e-9
                        if back and previous is not None and previous[4] > 0.0:
                            back = self._implausible(name, position - previous[0], header_stamp - previous[4]) is None
                        (self._off.discard if back else self._off.add)(name)
                if len(velocities) == len(names) and not self._velocities_from_positions:
                    velocity = float(velocities[index])
                elif previous is None or name in self._restarted:
                    velocity = 0.0
                    self._restarted.discard(name)
                    self._reference.pop(name, None)
                    self._candidates[name] = []
                else:
                    reference = self._reference_for(name, (previous[0], previous[2]), stamp)
                    velocity = velocity_from_positions(position, reference[0], stamp - reference[1], previous[1])
                self._joints[name] = (position, velocity, stamp, received, header_stamp)
            if jump is not None:
                self._latch = (f"{jump}; latched: holding until every joint reads back near its last trusted "
                               "position, or ~enable is called", received)
                self._off = {name for name in checked if name in self._trusted}
            elif self._latch is not None and not self._off:
                self._latch = None  # back where the arm could be: a one-message spike
            if self._latch is None:
                for name, position in checked.items():
                    self._trusted[name] = (position, header_stamp)
            if self._problem is not None and self._problem[2] <= set(names):
                self._problem = None  # a good message brought every joint the bad one was about
        return None

    def _reference_for(self, name: str, previous: Tuple[float, float], stamp: float) -> Tuple[float, float]:
        """The (position, stamp) to estimate against at ``stamp``: the newest earlier sample at
        least ``estimate_interval`` old, else the oldest one there is (lock held)."""
        if self._estimate_interval <= 0.0:
            return previous
        candidates = self._candidates.setdefault(name, [])
        candidates.append(previous)
        reference = self._reference.get(name)
        while candidates and stamp - candidates[0][1] >= self._estimate_interval - 1e-9:
            reference = candidates.pop(0)
        if reference is None:
            reference = candidates[0]
        self._reference[name] = reference
        return reference

    def restart_estimates(self) -> None:
        """A new episode: the next message's estimated velocities are 0.0, as an environment's
        first observation of an episode has them (``observation.joint_velocity_source:
        positions``), not the step from where the last episode left the arm. Positions and the
        glitch check keep their history."""
        with self._lock:
            self._restarted = set(self._known)

    def accept_current(self) -> Optional[str]:
        """An operator vouches that the arm stands where the newest joint states say (it was
        moved by hand, a simulator placed it): a latched jump clears and the current arm
        positions become the trusted ones.

        :return: the jump that was latched, or None.
        """
        with self._lock:
            latched = self._latch[0] if self._latch is not None else None
            self._latch, self._off = None, set()
            for name in self._max_speed:
                entry = self._joints.get(name)
                if entry is not None and entry[4] > 0.0:
                    self._trusted[name] = (entry[0], entry[4])
        return latched

    def latched_jump(self) -> Optional[str]:
        """Why the reader holds on a jump, or None."""
        with self._lock:
            return self._latch[0] if self._latch is not None else None

    def _implausible(self, name: str, moved: float, elapsed: float) -> Optional[str]:
        """Why a joint's move since its last message cannot be real motion, or None."""
        limit = self._max_speed.get(name)
        if limit is None or abs(moved) <= 1e-9:
            return None
        if elapsed < MIN_SAMPLE_INTERVAL:
            return f"{name} moved {moved:+.3f} rad within one stamp (no real motion)"
        if abs(moved) / elapsed > limit:
            return (f"{name} moved {moved:+.3f} rad in {elapsed * 1000:.0f} ms ({abs(moved) / elapsed:.1f} rad/s "
                    f"> {limit:.1f} rad/s, no real motion)")
        return None

    def _check(self, names: Sequence[str], positions: Sequence[float], velocities: Sequence[float]) -> Optional[str]:
        if len(positions) != len(names):
            return f"joint_states has {len(names)} names but {len(positions)} positions"
        if len(velocities) not in (0, len(names)):
            return f"joint_states has {len(names)} names but {len(velocities)} velocities"
        seen = set()
        for name in names:
            if name in seen:
                return f"joint_states names {name} twice: which value is true cannot be known"
            seen.add(name)
        try:
            values = [float(positions[i]) for i, name in enumerate(names) if name in self._known]
            if len(velocities) == len(names):
                values += [float(velocities[i]) for i, name in enumerate(names) if name in self._known]
        except (TypeError, ValueError):
            return "joint_states holds something that is not a number"
        if not all(math.isfinite(value) for value in values):
            return "joint_states positions or velocities contain NaN or inf"
        return None

    def reading(self) -> Optional[Reading[ArmJointState]]:
        """The merged state; None before any message; a problem when unusable."""
        with self._lock:
            if self._problem is not None:
                return Reading(None, self._problem[1], self._problem[0])
            if self._latch is not None:
                return Reading(None, self._latch[1], self._latch[0])
            missing = [name for name in self.arm_joint_names if name not in self._joints]
            if len(missing) == len(self.arm_joint_names):
                return None  # nothing of the arm yet (the gripper's driver may be first)
            if missing:
                newest = max(entry[3] for entry in self._joints.values())
                return Reading(None, newest, f"joint_states lacks {missing} (no message has named them)")
            arm = [self._joints[name] for name in self.arm_joint_names]
            fingers = [self._joints.get(name) for name in self.finger_joint_names]
        width = sum(f[0] for f in fingers) if fingers and all(f is not None for f in fingers) else None
        state = ArmJointState(np.array([a[0] for a in arm]), np.array([a[1] for a in arm]), width)
        # The state is as old as its oldest joint; without stamps on every joint it has none.
        return Reading(state, min(a[3] for a in arm), stamp=min(a[4] for a in arm))
