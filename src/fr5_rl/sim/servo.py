"""The arm driver's servo cycle, as the simulator reproduces it (no PyBullet needed).

The FAIRINO ros_control driver runs a 125 Hz loop: each cycle it reads the arm, lets the
position controller take the newest command, and writes it to the controller box as a
``ServoJ`` that acts from the *next* 8 ms cycle on. A command therefore waits for the next cycle
boundary, then one more cycle, before the arm starts moving toward it.
"""
from __future__ import annotations

from collections import deque
from typing import Deque, Optional, Sequence, Tuple


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

    def reset(self, targets: Sequence[float]) -> None:
        """Hold ``targets`` (rad) with nothing in flight, as after the driver starts."""
        self.applied: Tuple[float, ...] = tuple(float(value) for value in targets)
        self._latched = self.applied
        self._in_flight: Deque[Tuple[float, ...]] = deque([self.applied] * self.delay_cycles)
        self._steps = 0

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
