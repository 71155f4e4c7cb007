"""`rclpy.time.Time`: a point in time of a clock, in nanoseconds."""

from __future__ import annotations

from typing import Any

from twinfleet.rclpy.api.duration import Duration


class Time:
    """A time stamp. Under twinfleet, nanoseconds count from the fleet's common start."""

    __slots__ = ("nanoseconds", "clock_type")

    def __init__(self, *, seconds: float = 0, nanoseconds: int = 0, clock_type: Any = None) -> None:
        self.nanoseconds = int(seconds * 1_000_000_000) + int(nanoseconds)
        self.clock_type = clock_type

    def __repr__(self) -> str:
        return f"Time(nanoseconds={self.nanoseconds})"

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Time) and self.nanoseconds == other.nanoseconds

    def __hash__(self) -> int:
        return hash(self.nanoseconds)

    def __lt__(self, other: Time) -> bool:
        return self.nanoseconds < other.nanoseconds

    def __le__(self, other: Time) -> bool:
        return self.nanoseconds <= other.nanoseconds

    def __gt__(self, other: Time) -> bool:
        return self.nanoseconds > other.nanoseconds

    def __ge__(self, other: Time) -> bool:
        return self.nanoseconds >= other.nanoseconds

    def __add__(self, other: Duration) -> Time:
        return Time(nanoseconds=self.nanoseconds + other.nanoseconds, clock_type=self.clock_type)

    def __sub__(self, other: Any) -> Any:
        if isinstance(other, Time):
            return Duration(nanoseconds=self.nanoseconds - other.nanoseconds)
        return Time(nanoseconds=self.nanoseconds - other.nanoseconds, clock_type=self.clock_type)

    def seconds_nanoseconds(self) -> tuple[int, int]:
        """(whole seconds, remaining nanoseconds)."""
        sec, nanosec = divmod(self.nanoseconds, 1_000_000_000)
        return sec, nanosec

    def to_msg(self) -> Any:
        """A `builtin_interfaces/msg/Time`."""
        from twinfleet.rclpy.wire import load_interface
        sec, nanosec = self.seconds_nanoseconds()
        return load_interface("builtin_interfaces", "msg").Time(sec=sec, nanosec=nanosec)

    @classmethod
    def from_msg(cls, msg: Any, clock_type: Any = None) -> Time:
        """From a `builtin_interfaces/msg/Time`."""
        return cls(seconds=msg.sec, nanoseconds=msg.nanosec, clock_type=clock_type)
