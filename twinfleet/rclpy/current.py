"""Which node's callback runs now: futures that node code makes, loggers not tied to a
node and the blocking-idiom checks find the node's engine through it."""

from __future__ import annotations

from typing import Any

_RUNNING: list[Any] = []


def active_engine() -> Any:
    """The engine whose callback is running, or None."""
    return _RUNNING[-1] if _RUNNING else None


def enter(engine: Any) -> None:
    """A callback of `engine` starts."""
    _RUNNING.append(engine)


def leave() -> None:
    """The callback ends."""
    _RUNNING.pop()
