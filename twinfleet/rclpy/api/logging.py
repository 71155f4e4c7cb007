"""`rclpy.logging`: loggers whose lines, with their severity, go to the node's event log."""

from __future__ import annotations

import sys
from enum import IntEnum
from typing import Any


class LoggingSeverity(IntEnum):
    """rcutils' severities."""

    UNSET = 0
    DEBUG = 10
    INFO = 20
    WARN = 30
    ERROR = 40
    FATAL = 50


class RcutilsLogger:
    """A named logger; below its level (INFO by default) a line is dropped.

    Inside a callback a line becomes a ``ctx.log("rclpy.log", severity=..., logger=...,
    msg=...)`` record of the node (the live event log, the checker's trace); outside one
    (at import) it goes to stderr as rclpy's console output does.
    """

    def __init__(self, name: str = "", engine: Any = None) -> None:
        self.name = name
        self._engine = engine
        self._level = LoggingSeverity.INFO

    def _tf_ref(self) -> tuple[str, int] | None:
        return ("logger", 0) if self._engine is not None else None

    def get_child(self, name: str) -> RcutilsLogger:
        """The logger ``<name of this>.<name>``."""
        child = RcutilsLogger(f"{self.name}.{name}" if self.name else name, self._engine)
        child._level = self._level
        return child

    def set_level(self, level: LoggingSeverity | int) -> None:
        """Drop lines below `level`."""
        self._level = LoggingSeverity(level)

    def get_effective_level(self) -> LoggingSeverity:
        """The level in force."""
        return self._level

    def is_enabled_for(self, severity: LoggingSeverity | int) -> bool:
        """True when a line of `severity` is kept."""
        return severity >= self._level

    def log(self, message: Any, severity: LoggingSeverity | int, **_options: Any) -> bool:
        """Log `message` at `severity`; options (once, throttle_duration_sec, ...) are
        accepted and have no effect."""
        severity = LoggingSeverity(severity)
        if not self.is_enabled_for(severity):
            return False
        from twinfleet.rclpy.current import active_engine
        engine = self._engine or active_engine()
        if engine is not None:
            engine.log(severity.name, self.name, str(message))
        else:
            print(f"[{severity.name}] [{self.name}]: {message}", file=sys.stderr)
        return True

    def debug(self, message: Any, **options: Any) -> bool:
        """Log at DEBUG."""
        return self.log(message, LoggingSeverity.DEBUG, **options)

    def info(self, message: Any, **options: Any) -> bool:
        """Log at INFO."""
        return self.log(message, LoggingSeverity.INFO, **options)

    def warning(self, message: Any, **options: Any) -> bool:
        """Log at WARN."""
        return self.log(message, LoggingSeverity.WARN, **options)

    warn = warning

    def error(self, message: Any, **options: Any) -> bool:
        """Log at ERROR."""
        return self.log(message, LoggingSeverity.ERROR, **options)

    def fatal(self, message: Any, **options: Any) -> bool:
        """Log at FATAL."""
        return self.log(message, LoggingSeverity.FATAL, **options)


def get_logger(name: str) -> RcutilsLogger:
    """A logger not tied to a node (its lines go to the node whose callback runs)."""
    return RcutilsLogger(name)


def set_logger_level(name: str, level: LoggingSeverity | int) -> None:
    """Accepted; loggers made by `get_logger` start at INFO."""
