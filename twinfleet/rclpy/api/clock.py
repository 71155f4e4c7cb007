"""`rclpy.clock`: the node's clock reads the contract's time (`ctx.now()`)."""

from __future__ import annotations

from collections.abc import Callable
from enum import IntEnum

from twinfleet.rclpy.api.time import Time


class ClockType(IntEnum):
    """rclpy's clock types; every one reads the fleet's time here."""

    UNINITIALIZED = 0
    ROS_TIME = 1
    SYSTEM_TIME = 2
    STEADY_TIME = 3


class Clock:
    """A clock whose `now()` is the time the running callback sees (logical in the checker)."""

    def __init__(self, *, clock_type: ClockType = ClockType.ROS_TIME,
                 now_ms: Callable[[], int] | None = None) -> None:
        self.clock_type = clock_type
        self._now_ms = now_ms or (lambda: 0)

    def _tf_ref(self) -> tuple[str, int]:
        return ("clock", 0)

    def now(self) -> Time:
        """The current time: milliseconds since the fleet's start, as nanoseconds."""
        return Time(nanoseconds=self._now_ms() * 1_000_000, clock_type=self.clock_type)


class ROSClock(Clock):
    """The ROS clock."""
