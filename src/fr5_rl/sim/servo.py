"""The arm driver's servo cycle, as the simulator reproduces it (no PyBullet needed).

The FAIRINO ros_control driver runs a 125 Hz loop: each cycle it reads the arm, lets the
position controller take the newest command, and writes it to the controller box as a
``ServoJ`` that acts from the *next* 8 ms cycle on. A command therefore waits for the next cycle
boundary, then one more cycle, before the arm starts moving toward it.
"""
from __future__ import annotations

import math
from collections import deque
from typing import Deque, List, Optional, Sequence, Tuple

from ..config import ConfigError, whole_multiple


class ServoCycle:
    """Latches commands on a fixed cycle and releases them ``delay_cycles`` cycles later.

    Time is counted in physics steps so that it stays exact: the cycle is a whole number of
    steps. With ``steps_per_cycle`` = 0 there is no cycle: a command acts from the next
    physics step on (an ideal driver).

    :param steps_per_cycle: physics steps per servo cycle (0: no cycle).
    :param delay_cycles: whole cycles between latching a command and its effect.
    :param initial: the joint targets (rad) the arm holds before any command.
    """

    def __init__(self, steps_per_cycle: int, delay_cycles: int, initial: Sequence[float]) -> None:
        if steps_per_cycle < 0 or delay_cycles < 0:
            raise ValueError(f"steps_per_cycle ({steps_per_cycle}) and delay_cycles ({delay_cycles}) must be >= 0")
        self.steps_per_cycle = int(steps_per_cycle)
        self.delay_cycles = int(delay_cycles) if steps_per_cycle else 0
        self.reset(initial)

    def reset(self, targets: Sequence[float], restart_cycle: bool = True, phase_steps: int = 0) -> None:
        """Hold ``targets`` (rad) with nothing in flight.

        :param restart_cycle: True: the next step begins a cycle, as after the driver starts;
            False: the cycle keeps its phase (a real driver's loop runs on across episodes).
        :param phase_steps: with ``restart_cycle``, the physics steps already done in the first
            cycle (0 .. steps_per_cycle - 1): where the cycle's boundaries fall.
        """
        self.applied: Tuple[float, ...] = tuple(float(value) for value in targets)
        self._latched = self.applied
        self._in_flight: Deque[Tuple[float, ...]] = deque([self.applied] * self.delay_cycles)
        if restart_cycle or not hasattr(self, "_steps"):
            self._steps = int(phase_steps) % self.steps_per_cycle if self.steps_per_cycle else 0

    def targets_for_step(self, newest_command: Optional[Sequence[float]]) -> Tuple[float, ...]:
        """The targets the arm tracks during the next physics step.

        :param newest_command: the newest command received (rad), or None if none yet; on a
            cycle boundary it is latched.
        """
        if self.steps_per_cycle == 0:
            if newest_command is not None:
                self.applied = tuple(newest_command)
            return self.applied
        if self._steps % self.steps_per_cycle == 0:
            if newest_command is not None:
                self._latched = tuple(newest_command)
            self._in_flight.append(self._latched)
            self.applied = self._in_flight.popleft()
        self._steps += 1
        return self.applied


class FirstOrderResponse:
    """How a servo follows the targets it is given: a first-order lag per joint.

    Each physics step every joint's applied target moves the fraction ``1 - exp(-dt / tau)``
    of the way to the newest target: a step command is followed with time constant ``tau``.
    A real controller filters and tracks its servo stream (the FR5's ``ServoJ`` takes a filter
    time), with a response that differs per joint as the loads do; a stiff simulated position
    controller has almost none. A lag is what a driver profile can state and the fit can
    recover; tau = 0 leaves a joint's targets as they are.

    :param time_constants: (n,) tau per joint (s, >= 0), controller order; empty: no lag.
    :param physics_dt: the physics step (s) between calls of :meth:`targets_for_step`.
    :param initial: the targets (rad) held before any command.
    """

    def __init__(self, time_constants: Sequence[float], physics_dt: float, initial: Sequence[float]) -> None:
        if any(not math.isfinite(tau) or tau < 0.0 for tau in time_constants):
            raise ValueError(f"response time constants must be finite and >= 0 s, got {list(time_constants)}")
        if physics_dt <= 0.0:
            raise ValueError(f"physics_dt must be > 0 s, got {physics_dt}")
        self.time_constants = tuple(float(tau) for tau in time_constants)
        self._fractions = [1.0 - math.exp(-physics_dt / tau) if tau > 0.0 else 1.0 for tau in self.time_constants]
        self.active = any(tau > 0.0 for tau in self.time_constants)
        self.reset(initial)

    def reset(self, targets: Sequence[float]) -> None:
        """Hold ``targets`` (rad): the joints are at rest there."""
        self.applied: List[float] = [float(value) for value in targets]

    def targets_for_step(self, targets: Sequence[float]) -> Tuple[float, ...]:
        """The lagged targets (rad) for the next physics step, given the servo's ``targets``."""
        if not self.active:
            self.applied = [float(value) for value in targets]
            return tuple(self.applied)
        if len(targets) != len(self._fractions):
            raise ValueError(f"{len(targets)} targets for {len(self._fractions)} response time constants")
        self.applied = [held + fraction * (float(target) - held)
                        for held, target, fraction in zip(self.applied, targets, self._fractions)]
        return tuple(self.applied)


class DriverModel:
    """The arm's driver as every real-time stand-in runs it (the simulator node, the chain
    emulation, the replay of a recording): commands latched on the servo cycle
    (:class:`ServoCycle`), then followed with the response lag (:class:`FirstOrderResponse`).

    :param servo_rate: Hz of the driver's servo loop (0: no cycle, a command acts from the next
        physics step).
    :param servo_delay_cycles: whole cycles between latching a command and its effect.
    :param response_time_constants: s per joint (empty or zeros: no lag).
    :param physics_dt: s per physics step; 1 / ``servo_rate`` must be a whole multiple of it.
    :param initial: rad, the targets held before any command.
    :raises ConfigError: the servo period is not a whole number of physics steps.
    """

    def __init__(self, servo_rate: float, servo_delay_cycles: int, response_time_constants: Sequence[float],
                 physics_dt: float, initial: Sequence[float]) -> None:
        steps_per_cycle = 0
        if servo_rate > 0:
            steps_per_cycle = whole_multiple(1.0 / servo_rate, physics_dt)
            if steps_per_cycle is None:
                raise ConfigError(f"1 / servo_rate ({1.0 / servo_rate:g} s) must be a whole multiple of "
                                  f"physics_dt ({physics_dt:g} s)")
        self.servo = ServoCycle(steps_per_cycle, servo_delay_cycles, initial)
        self.response = FirstOrderResponse(response_time_constants, physics_dt, initial)

    def reset(self, positions: Sequence[float], restart_cycle: bool = True, phase_steps: int = 0) -> None:
        """The arm stands at ``positions`` (rad), nothing in flight (see :meth:`ServoCycle.reset`)."""
        self.servo.reset(positions, restart_cycle=restart_cycle, phase_steps=phase_steps)
        self.response.reset(positions)

    def targets_for_step(self, newest_command: Optional[Sequence[float]]) -> Tuple[float, ...]:
        """The joint targets (rad) for the next physics step, given the newest command received
        (None: none yet)."""
        return self.response.targets_for_step(self.servo.targets_for_step(newest_command))
