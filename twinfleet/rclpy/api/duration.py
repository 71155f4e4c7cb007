"""`rclpy.duration.Duration`: a span of time in nanoseconds."""

from __future__ import annotations

from typing import Any


class Duration:
    """A duration; built from seconds and/or nanoseconds as in rclpy."""

    __slots__ = ("nanoseconds",)

    def __init__(self, *, seconds: float = 0, nanoseconds: int = 0) -> None:
        self.nanoseconds = int(seconds * 1_000_000_000) + int(nanoseconds)

    def __repr__(self) -> str:
        return f"Duration(nanoseconds={self.nanoseconds})"

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Duration) and self.nanoseconds == other.nanoseconds

    def __lt__(self, other: Duration) -> bool:
        return self.nanoseconds < other.nanoseconds

    def __le__(self, other: Duration) -> bool:
        return self.nanoseconds <= other.nanoseconds

    def __gt__(self, other: Duration) -> bool:
        return self.nanoseconds > other.nanoseconds

    def __ge__(self, other: Duration) -> bool:
        return self.nanoseconds >= other.nanoseconds

    def __hash__(self) -> int:
        return hash(self.nanoseconds)

    def to_msg(self) -> Any:
        """A `builtin_interfaces/msg/Duration`."""
        from twinfleet.rclpy.wire import load_interface
        sec, nanosec = divmod(self.nanoseconds, 1_000_000_000)
        return load_interface("builtin_interfaces", "msg").Duration(sec=sec, nanosec=nanosec)

    @classmethod
    def from_msg(cls, msg: Any) -> Duration:
        """From a `builtin_interfaces/msg/Duration`."""
        return cls(seconds=msg.sec, nanoseconds=msg.nanosec)
