"""The gripper bridge's pure decisions and small helpers: no network, no threads of its own.

Binary mode's hysteresis, the read-back's debounce, the retry
backoff and the throttled error log. :mod:`fr5_rl.drivers.gripper_bridge` puts them to work;
percent ↔ width and the deadband are :mod:`fr5_rl.gripper`'s, shared with the environment.
"""
from __future__ import annotations

import threading
import time
from typing import Callable, Dict, Optional

OPEN, CLOSED = "open", "closed"

Report = Callable[[str, str], None]  # (level: "error" | "warn" | "info", message)


def transient_zero(raw_percent: float, now: float, last_move_at: Optional[float], window: float) -> bool:
    """Whether a position reading is the controller's transient 0 right after a move (field report:
    ``GetGripperCurPosition`` reads 0 for a moment after ``MoveGripper``), to be ignored.

    A 0 that is still read once ``window`` has passed since the move is real (e.g. closed on nothing).

    :param raw_percent: the controller's reading, before any inversion (%).
    :param now: the clock's time of the reading (s).
    :param last_move_at: when the latest ``MoveGripper`` was sent (s); None: none yet.
    :param window: how long after a move a 0 is distrusted (s).
    """
    return raw_percent <= 0.0 and last_move_at is not None and now - last_move_at < window


def binary_state(width: float, current: Optional[str], threshold: float, hysteresis: float) -> str:
    """Open or closed for a width, with hysteresis so noise near the threshold does not chatter.

    :param width: opening width (m).
    :param current: the state decided for the previous width (None before the first one).
    :param threshold: width (m) separating closed from open.
    :param hysteresis: half-width (m) of the band around ``threshold`` that keeps ``current``.
    """
    if width < threshold - hysteresis:
        return CLOSED
    if width > threshold + hysteresis:
        return OPEN
    if current is None:  # first command inside the band: the threshold alone decides
        return CLOSED if width < threshold else OPEN
    return current


class Backoff:
    """Exponential retry delays: ``initial``, 2×, 4× … capped at ``maximum``.

    :param initial: first delay (s).
    :param maximum: longest delay (s).
    """

    def __init__(self, initial: float, maximum: float) -> None:
        self.initial, self.maximum = initial, maximum
        self.failures = 0

    def next_delay(self) -> float:
        """Delay (s) before the next attempt after one more failure."""
        delay = min(self.maximum, self.initial * (2.0 ** self.failures))
        self.failures += 1
        return delay

    def reset(self) -> None:
        """Start again from ``initial`` (after a success)."""
        self.failures = 0


class ThrottledReport:
    """Passes messages on, at most one per ``period`` (s) for each kind of problem.

    The first message of a kind goes through at once; repeats inside the period are counted
    and the count is added to the next one that goes through.

    :param report: where messages go, ``report(level, text)``.
    :param period: seconds between two messages of one kind (0: no throttling).
    :param clock: monotonic time source (s).
    """

    def __init__(self, report: Report, period: float, clock: Callable[[], float] = time.monotonic) -> None:
        self.report, self.period, self.clock = report, period, clock
        self.lock = threading.Lock()
        self.last: Dict[str, float] = {}
        self.suppressed: Dict[str, int] = {}

    def __call__(self, level: str, kind: str, text: str) -> None:
        """Pass ``text`` on unless a message of ``kind`` went through less than ``period`` ago.

        :param level: "error", "warn" or "info".
        :param kind: the kind of problem the throttling counts by (e.g. "unreachable").
        :param text: the message.
        """
        now = self.clock()
        with self.lock:
            last = self.last.get(kind)
            if last is not None and now - last < self.period:
                self.suppressed[kind] = self.suppressed.get(kind, 0) + 1
                return
            self.last[kind] = now
            count = self.suppressed.pop(kind, 0)
        self.report(level, text + (f" ({count} more like this in the last {self.period:g} s)" if count else ""))

    def forget(self, kind: str) -> None:
        """Let the next message of ``kind`` through at once (the problem was resolved)."""
        with self.lock:
            self.last.pop(kind, None)
            self.suppressed.pop(kind, None)


