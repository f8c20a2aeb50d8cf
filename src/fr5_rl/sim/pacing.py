"""Pacing a simulation against a wall clock, without ROS: the simulator node's real-time loop.

:class:`WallClockPacer` keeps simulated time, counted in whole physics steps, locked to a wall
clock; :class:`StepSchedule`, :class:`AlignedStepSchedule` and :class:`TimeSchedule` say when
something periodic (a verdict, a publication, a camera frame) is due on that simulated time;
:class:`ArrivalQueue` gives each physics step the commands that had arrived when it began.
The clock is injected, so all of it is tested without sleeping.
"""
from __future__ import annotations

import time
from collections import deque
from typing import Callable, Deque, Generic, Iterator, Optional, Tuple, TypeVar

T = TypeVar("T")


class WallClockPacer:
    """Simulated time in whole physics steps, kept locked to a wall clock as a real arm's is.

    :param physics_dt: s of simulated time per physics step.
    :param max_catch_up: most steps one call of :meth:`due_steps` runs: a loop that woke very
        late catches up over several wake-ups instead of stalling its outputs.
    :param max_lag: s the simulation may fall behind the wall clock before it is resynchronised
        (the missed time is dropped rather than raced through).
    :param clock: wall clock in s (monotonic).
    """

    def __init__(self, physics_dt: float, max_catch_up: int, max_lag: float = 1.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.physics_dt = physics_dt
        self.max_catch_up = max_catch_up
        self.max_lag = max_lag
        self._clock = clock
        self._start = clock()
        self.step = 0  # physics steps run: simulated time is step * physics_dt

    @property
    def sim_time(self) -> float:
        """Simulated time (s) since the start."""
        return self.step * self.physics_dt

    @property
    def wall_time(self) -> float:
        """When, on the wall clock (s, the clock's own), the simulated arm is where the last
        step left it: what a driver stamps the state it read with, however late the loop ran."""
        return self._start + self.sim_time

    def lateness(self) -> float:
        """How far (s) the simulation is behind the wall clock now: the time a loop that woke late
        has to catch up on (0 to one physics step when on time)."""
        return self._clock() - self._start - self.sim_time

    def due_steps(self) -> Iterator[int]:
        """The physics steps the wall clock says are due now, each yielded after it is counted
        (the caller runs it): a command then acts as long in simulation as it did in reality,
        however late the loop woke."""
        wall = self._clock() - self._start
        caught_up = 0
        while self.step * self.physics_dt < wall - 0.5 * self.physics_dt and caught_up < self.max_catch_up:
            self.step += 1
            caught_up += 1
            yield self.step
        lag = wall - self.sim_time
        if lag > self.max_lag:  # hopelessly behind: resynchronise rather than race
            self._start += lag


class ArrivalQueue(Generic[T]):
    """Commands kept with their arrival time, each taken up by the first physics step that runs
    at or after it: a loop catching up on late steps must not apply a command in simulated time
    before it arrived in reality. Arm and gripper commands go through one, so that a late loop
    cannot make the fingers lead the arm.
    """

    def __init__(self) -> None:
        self._pending: Deque[Tuple[float, T]] = deque()

    def push(self, arrived: float, command: T) -> None:
        """:param arrived: wall-clock time (s, the pacer's clock) the command arrived.
        :param command: the command, whatever the caller applies."""
        self._pending.append((arrived, command))

    def due(self, step_start: float) -> Optional[T]:
        """The newest command that arrived at or before ``step_start`` (s, the pacer's clock; the
        others before it are dropped, superseded), or None when none is due."""
        command = None
        pending = self._pending
        while pending and pending[0][0] <= step_start:
            command = pending.popleft()[1]
        return command

    def clear(self) -> None:
        """Forget every command not yet taken up (a reset, a hold)."""
        self._pending.clear()

    def __len__(self) -> int:
        return len(self._pending)


class StepSchedule:
    """Due every ``period`` steps, counted from the last :meth:`restart`.

    :param period: steps between two due steps (>= 1).
    """

    def __init__(self, period: int) -> None:
        self.period = period
        self.next = 0

    def restart(self, step: int) -> None:
        """Count the period anew from ``step``: the next due step is ``step + period``."""
        self.next = step + self.period

    def due(self, step: int) -> bool:
        """True once per period, at the first step at or past the due one."""
        if step < self.next:
            return False
        self.next += self.period
        return True


class AlignedStepSchedule:
    """Due at whole multiples of ``period`` steps (the first call is due): publications stay on
    a fixed grid of simulated time however the loop wakes.

    :param period: steps between two due steps (>= 1).
    """

    def __init__(self, period: int) -> None:
        self.period = period
        self.next = 0

    def due(self, step: int) -> bool:
        if step < self.next:
            return False
        self.next = step + self.period - step % self.period
        return True


class TimeSchedule:
    """Due every ``period`` s of simulated time, from the time it was last due.

    :param period: s between two due times.
    """

    def __init__(self, period: float) -> None:
        self.period = period
        self.next = 0.0

    def due(self, now: float) -> bool:
        if now < self.next:
            return False
        self.next = now + self.period - 1e-9  # a period of float time that lands a hair short still counts
        return True
