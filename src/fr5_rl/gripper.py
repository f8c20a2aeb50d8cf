"""The gripper as the FR5 controller serves it: percent <-> width, the command deadband, and the
opening as a policy sees it through the gripper bridge.

The bridge (:mod:`fr5_rl.drivers.gripper_bridge`) and the environment's randomisation
(``randomisation.gripper_bridge_share``) both use these functions, so that the gripper a policy
meets in training is the one the bridge gives it on the real cell. No ROS, no PyBullet.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

from .config import ConfigError, load_yaml

def width_to_percent(width: float, max_width: float, invert: bool = False) -> int:
    """The ``MoveGripper`` position for an opening width.

    :param width: opening width (m), already inside 0 … ``max_width``.
    :param max_width: the gripper's largest opening (m), = 100 %.
    :param invert: True when the controller counts 0 % as open.
    :return: whole percent 0 … 100 (the SDK takes integers).
    """
    percent = min(100, max(0, int(round(100.0 * width / max_width))))
    return 100 - percent if invert else percent


def percent_to_width(percent: float, max_width: float, invert: bool = False) -> float:
    """The opening width a ``GetGripperCurPosition`` percentage stands for (the inverse of
    :func:`width_to_percent`).

    :param percent: the controller's position, 0 … 100 (clamped into that range).
    :param max_width: the gripper's largest opening (m), = 100 %.
    :param invert: True when the controller counts 0 % as open.
    :return: opening width (m).
    """
    percent = min(100.0, max(0.0, float(percent)))
    return max_width * ((100.0 - percent) if invert else percent) / 100.0


def needs_move(target: int, sent: Optional[int], deadband: int) -> bool:
    """Whether a new ``MoveGripper`` is worth sending.

    The end stops are always reached exactly: a deadband must not leave the gripper 1 % short
    of fully closed around an object.

    :param target: percent wanted now.
    :param sent: percent last acknowledged by the controller (None: unknown, e.g. after a reconnect).
    :param deadband: smallest change (percent) that is sent.
    """
    if sent is None:
        return True
    if target == sent:
        return False
    return abs(target - sent) >= deadband or target in (0, 100)


@dataclass(frozen=True)
class BridgeTiming:
    """What the gripper bridge does to the gripper, from config/gripper_bridge.yaml.

    :param call_period: s between two ``MoveGripper`` calls at most (1 / ``max_call_rate``).
    :param read_period: s between two ``GetGripperCurPosition`` read-backs (1 / ``readback_rate``).
    :param deadband_percent: smallest change (%) sent as a new ``MoveGripper``.
    :param zero_debounce: s after a ``MoveGripper`` in which the bridge drops a read-back of 0 %
        (the controller reads 0 for a moment after a move): a read that falls in the controller's
        transient is lost, and the policy keeps seeing the older one.
    :param read_max_age: s: a read-back older than this holds the next move until a read lands
        past the transient (``readback_max_age``; 0: off).
    :param read_retry: s between two reads while a move waits on one (``readback_retry``).
    """

    call_period: float
    read_period: float
    deadband_percent: int
    zero_debounce: float
    read_max_age: float = 0.0
    read_retry: float = 0.0


class BridgedGripper:
    """The gripper behind the bridge, for a simulation that steps in control periods.

    Commands: a new width goes out as whole percent, only when it moved past the deadband (the
    end stops always), and at most once per ``call_period``; the fingers carry out the last one
    sent. Observation: the opening read back every ``read_period`` in whole percent, held in
    between; a read within the controller's zero transient after a move reads 0 and is dropped,
    as the bridge drops it (:func:`fr5_rl.drivers.gripper_decisions.transient_zero`). A read-back
    older than ``read_max_age`` holds a move until a read gets through, reads then coming every
    ``read_retry``, as the bridge schedules them. Both clocks start at a random phase and the
    transient is drawn per episode (:meth:`reset`).

    :param timing: the bridge's rates and deadband.
    :param max_width: the gripper's largest opening (m), = 100 %.
    """

    def __init__(self, timing: BridgeTiming, max_width: float) -> None:
        self.timing, self.max_width = timing, max_width
        self.sent: Optional[int] = None
        self.next_call = self.next_read = 0.0
        self.read_width = max_width
        self.read_at = 0.0  # s: when the newest accepted read-back was taken
        self.last_read_try: Optional[float] = None  # s: the newest read, accepted or lost
        self.move_waiting = False  # a move waits on a fresh read-back
        self.last_move_at: Optional[float] = None
        self.zero_transient = 0.0

    def reset(self, width: float, call_phase: float, read_phase: float, zero_transient: float = 0.0) -> None:
        """A new episode with the fingers at ``width`` (m), sent and read back.

        :param call_phase: s until the first call may go out (0 … call_period).
        :param read_phase: s until the first read-back (0 … read_period).
        :param zero_transient: s the controller reads 0 after a move (0 … the bridge's
            ``zero_debounce``; longer ones the bridge would pass on as a real 0).
        """
        self.sent = width_to_percent(width, self.max_width)
        self.read_width = percent_to_width(self.sent, self.max_width)
        self.next_call, self.next_read = call_phase, read_phase
        self.read_at, self.last_read_try, self.move_waiting = 0.0, None, False
        self.last_move_at, self.zero_transient = None, min(zero_transient, self.timing.zero_debounce)

    def _stale(self, now: float) -> bool:
        """Whether the newest read-back is older than ``read_max_age`` at ``now`` (s)."""
        return self.timing.read_max_age > 0 and now - self.read_at > self.timing.read_max_age

    def command(self, width: float, now: float) -> float:
        """The width (m) the fingers are told to take at ``now`` (s) when ``width`` is wanted."""
        wanted = width_to_percent(min(self.max_width, max(0.0, width)), self.max_width)
        self.move_waiting = False
        if now >= self.next_call and needs_move(wanted, self.sent, self.timing.deadband_percent):
            if self._stale(now):
                self.move_waiting = True  # the read goes first
            else:
                self.sent = wanted
                self.next_call = now + self.timing.call_period
                self.last_move_at = now
        return percent_to_width(self.sent, self.max_width)

    def observe(self, measured_width: float, now: float) -> float:
        """The opening (m) the policy sees at ``now`` (s): the newest read-back of the fingers."""
        retry = (self.move_waiting and self.last_read_try is not None
                 and now >= self.last_read_try + min(self.timing.read_retry, self.timing.read_period))
        if now >= self.next_read or retry:
            self.last_read_try = now
            in_transient = self.last_move_at is not None and now - self.last_move_at < self.zero_transient
            if not in_transient:
                self.read_width = percent_to_width(width_to_percent(min(self.max_width, max(0.0, measured_width)),
                                                                    self.max_width), self.max_width)
                self.read_at = now
            while self.next_read <= now:
                self.next_read += self.timing.read_period
        return self.read_width


def load_bridge_timing(config_name: str = "gripper_bridge") -> BridgeTiming:
    """:class:`BridgeTiming` from the bridge's parameter file (``max_call_rate``, ``readback_rate``,
    ``deadband_percent``, ``zero_debounce``): the environment models the bridge the node runs.

    :raises ConfigError: a rate that is not positive (a read-back rate of 0, off, leaves a
        policy that observes the opening without any reading).
    """
    params = load_yaml(config_name)
    call_rate, read_rate = float(params["max_call_rate"]), float(params["readback_rate"])
    if call_rate <= 0 or read_rate <= 0:
        raise ConfigError(f"config/{config_name}.yaml: max_call_rate ({call_rate:g}) and readback_rate ({read_rate:g}) "
                          "must be positive for the environment to model the bridge")
    return BridgeTiming(1.0 / call_rate, 1.0 / read_rate, int(params["deadband_percent"]), float(params["zero_debounce"]),
                        float(params["readback_max_age"]), float(params["readback_retry"]))
