"""`rclpy.exceptions`: the errors rclpy raises that nodes catch, and twinfleet's own refusals."""

from __future__ import annotations


class ROSInterruptException(Exception):
    """rclpy was shut down while waiting."""


class ParameterException(Exception):
    """A parameter operation failed."""


class ParameterNotDeclaredException(ParameterException):
    """A parameter was read or set before it was declared."""

    def __init__(self, name: str) -> None:
        super().__init__(f"parameter {name!r} is not declared")


class ParameterAlreadyDeclaredException(ParameterException):
    """A parameter was declared twice."""

    def __init__(self, name: str) -> None:
        super().__init__(f"parameter {name!r} is already declared")


class InvalidParameterTypeException(ParameterException):
    """A parameter was set to a value of another type than its declared one."""


class InvalidParameterValueException(ParameterException):
    """An on-set-parameters callback refused a value."""


class ParameterUninitializedException(ParameterException):
    """A parameter declared without a value was read."""

    def __init__(self, name: str) -> None:
        super().__init__(f"parameter {name!r} has no value")


class NotSupportedError(NotImplementedError):
    """A part of rclpy that twinfleet does not offer yet; the text says which and what to do."""
