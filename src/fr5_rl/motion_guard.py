"""What a real arm needs around the policy: a slow move into the training start distribution
before the policy takes over, a velocity limit that ramps in after every pause, and a margin from
the joint limits.

:class:`MotionGuard` is pure logic on joint positions (rad), driven once a control period by
:class:`~fr5_rl.deploy.deployment.DeploymentStep`; its settings are the ``guard`` section of
``config/policy_node.yaml``. It sits with the action shaping (the shared layer), not in
``deploy``: the environment runs the same ramp and margin where ``randomisation.guard_share``
asks for them, so that a policy can train on what the node does to its first commands.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Optional, Sequence, Tuple

import numpy as np

from .config import ConfigError, RobotSpec, check_positive, load_yaml, typed


@dataclass(frozen=True)
class MotionGuardSettings:
    """``guard`` of ``config/policy_node.yaml``.

    :param joint_limit_margin: rad a command keeps from every joint limit (a target already
        beyond it may not go further out).
    :param ramp_time: s over which the velocity limit ramps from 0 to the FR5's after ~enable,
        any hold, or the hand-over from the start move.
    :param glitch_speed_factor: a measured state implying a joint speed above this many times
        the arm's rated speed is a jump no real motion makes: hold (latched, see
        ``jump_recovery_window``).
    :param jump_recovery_window: s the arm can have gone on moving on its last command after a
        jump made the node hold; a latched jump clears when every joint is back within rated
        speed x this of the last state it trusted (a one-message spike), or on ``~enable``.
    :param start_speed: rad/s of the slowest-joint-synchronised start move (at most 0.3).
    :param start_arrival: rad from the start pose (every joint) at which the start move hands
        over to the policy ...
    :param start_settle_speed: ... once no joint moves faster than this (rad/s): a training
        episode starts at rest.
    :param go_to_start: move into the training start distribution by itself when the arm is
        outside it; False: hold with the distance until ``~go_to_start`` is called.
    """

    joint_limit_margin: float
    ramp_time: float
    glitch_speed_factor: float
    jump_recovery_window: float
    start_speed: float
    start_arrival: float
    start_settle_speed: float
    go_to_start: bool

    def check(self, source: str) -> None:
        check_positive(source, **{"guard.ramp_time": self.ramp_time, "guard.start_speed": self.start_speed,
                                  "guard.start_arrival": self.start_arrival,
                                  "guard.start_settle_speed": self.start_settle_speed,
                                  "guard.jump_recovery_window": self.jump_recovery_window})
        if self.start_speed > 0.3:
            raise ConfigError(f"{source}: 'guard.start_speed' {self.start_speed} rad/s: the start move is a slow "
                              "one, at most 0.3 rad/s")
        if self.joint_limit_margin < 0 or self.glitch_speed_factor <= 1.0:
            raise ConfigError(f"{source}: 'guard.joint_limit_margin' must be >= 0 rad and "
                              f"'guard.glitch_speed_factor' above 1, got {self.joint_limit_margin}, "
                              f"{self.glitch_speed_factor}")


def load_guard_settings(config_name: str = "policy_node") -> MotionGuardSettings:
    """The policy node's guard (``guard`` of config/<config_name>.yaml), as it runs on every chain."""
    return typed(MotionGuardSettings, load_yaml(config_name)["guard"], f"config/{config_name}.yaml", "guard")


class StartPhase(enum.Enum):
    """Where the arm stands against the training start distribution."""

    CHECK = "check"        # not looked at since ~enable or the episode began
    MOVING = "moving"      # on the slow move to the start pose
    REFUSED = "refused"    # outside the distribution, no move asked for
    RUNNING = "running"    # the policy has the arm


class MotionGuard:
    """The start move, the ramp-in and the joint-limit margin of one arm.

    :param robot: limits and velocity limits.
    :param settings: see :class:`MotionGuardSettings`.
    :param start_pose: rad, the centre of the training start distribution (the home pose).
    :param start_spread: rad, how far any joint may be from ``start_pose`` at a training start
        (``<task>.start_joint_noise``).
    :param control_dt: s per control period.
    """

    def __init__(self, robot: RobotSpec, settings: MotionGuardSettings, start_pose: Sequence[float],
                 start_spread: float, control_dt: float) -> None:
        self.settings = settings
        self.start_pose = np.asarray(start_pose, dtype=np.float64)
        self.start_spread = float(start_spread)
        self.control_dt = float(control_dt)
        self.lower = robot.lower_limits + settings.joint_limit_margin
        self.upper = robot.upper_limits - settings.joint_limit_margin
        self.velocity_limits = robot.velocity_limits
        self.phase = StartPhase.CHECK
        self.go_to_start_asked = False  # a one-shot ~go_to_start
        self._ramp_start: Optional[float] = None

    def restart(self) -> None:
        """Look at the start again (~enable, a new episode)."""
        self.phase = StartPhase.CHECK
        self._ramp_start = None

    def pause(self) -> None:
        """A hold: the next command ramps in again."""
        self._ramp_start = None

    def distance_from_start(self, measured: Sequence[float]) -> Tuple[float, int]:
        """The largest joint distance (rad) from the start pose, and its joint index."""
        gaps = np.abs(np.asarray(measured, dtype=np.float64) - self.start_pose)
        joint = int(np.argmax(gaps))
        return float(gaps[joint]), joint

    def start_move(self, measured: Sequence[float], velocities: Optional[Sequence[float]] = None
                   ) -> Tuple[Optional[np.ndarray], Optional[str]]:
        """Before the policy runs: ``(targets, None)`` for one period of the start move,
        ``(None, why)`` to refuse (far from the start, no move asked for), or ``(None, None)``
        when the policy may take over.

        :param velocities: rad/s of the joints, if known: the move hands over at rest."""
        distance, joint = self.distance_from_start(measured)
        if self.phase is StartPhase.CHECK or self.phase is StartPhase.REFUSED:
            if distance <= self.start_spread:
                self.phase = StartPhase.RUNNING
                return None, None
            if not (self.settings.go_to_start or self.go_to_start_asked):
                self.phase = StartPhase.REFUSED
                return None, (f"the arm is {distance:.3f} rad from the training start on j{joint + 1} (training starts "
                              f"within {self.start_spread:.3f} rad of home): call ~go_to_start for a slow move there, "
                              "or move it by hand")
            self.phase = StartPhase.MOVING
            self.go_to_start_asked = False
        at_rest = velocities is None or max(abs(float(v)) for v in velocities) <= self.settings.start_settle_speed
        if distance <= self.settings.start_arrival and at_rest:
            self.phase = StartPhase.RUNNING
            return None, None
        measured = np.asarray(measured, dtype=np.float64)
        gap = self.start_pose - measured
        if distance <= 0.0:
            return measured, None  # there, still settling: stand and let it come to rest
        # Every joint arrives together: the slowest-joint step scales all of them.
        scale = min(1.0, self.settings.start_speed * self.control_dt / distance)
        return measured + gap * scale, None

    def limit(self, targets: Sequence[float], measured: Sequence[float], now: float) -> np.ndarray:
        """The policy's targets (rad) within the ramped velocity limit and the joint-limit margin.

        :param now: s on the caller's monotonic clock.
        """
        if self._ramp_start is None:
            self._ramp_start = now
        share = min(1.0, (now - self._ramp_start + self.control_dt) / self.settings.ramp_time)
        measured = np.asarray(measured, dtype=np.float64)
        step = self.velocity_limits * self.control_dt * share
        limited = np.clip(np.asarray(targets, dtype=np.float64), measured - step, measured + step)
        # A joint already inside the margin may stay or come back, not go further out.
        return np.clip(limited, np.minimum(self.lower, measured), np.maximum(self.upper, measured))
