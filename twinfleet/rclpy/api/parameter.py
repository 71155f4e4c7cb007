"""`rclpy.parameter.Parameter`: a name, a type and a value."""

from __future__ import annotations

from enum import Enum
from types import SimpleNamespace
from typing import Any


class Parameter:
    """A parameter as rclpy passes it around."""

    class Type(Enum):
        """rcl_interfaces' parameter types."""

        NOT_SET = 0
        BOOL = 1
        INTEGER = 2
        DOUBLE = 3
        STRING = 4
        BYTE_ARRAY = 5
        BOOL_ARRAY = 6
        INTEGER_ARRAY = 7
        DOUBLE_ARRAY = 8
        STRING_ARRAY = 9

        @classmethod
        def from_parameter_value(cls, value: Any) -> Parameter.Type:
            """The type of a Python value."""
            return type_of(value)

        def check(self, value: Any) -> bool:
            """True when `value` is of this type."""
            return self is Parameter.Type.NOT_SET or type_of(value) is self

    def __init__(self, name: str, type_: Parameter.Type | None = None, value: Any = None) -> None:
        if type_ is None:
            type_ = type_of(value)
        if not type_.check(value) and not (type_ is Parameter.Type.DOUBLE
                                           and type(value) is int):
            raise TypeError(f"parameter {name!r}: {value!r} is not of type {type_.name}")
        self.name = name
        self.type_ = type_
        self.value = float(value) if type_ is Parameter.Type.DOUBLE and value is not None else value

    def __repr__(self) -> str:
        return f"Parameter({self.name!r}, {self.type_.name}, {self.value!r})"

    def __eq__(self, other: object) -> bool:
        return (isinstance(other, Parameter) and (self.name, self.type_, self.value)
                == (other.name, other.type_, other.value))

    def __hash__(self) -> int:
        return hash((self.name, self.type_))

    @property
    def type(self) -> Parameter.Type:
        """The type (rclpy spells it both ways)."""
        return self.type_

    def get_parameter_value(self) -> Any:
        """The value in rcl_interfaces' ParameterValue shape (``.double_value`` ...)."""
        names = ("bool_value", "integer_value", "double_value", "string_value",
                 "byte_array_value", "bool_array_value", "integer_array_value",
                 "double_array_value", "string_array_value")
        fields: dict[str, Any] = {n: ([] if "array" in n else None) for n in names}
        fields.update(bool_value=False, integer_value=0, double_value=0.0, string_value="")
        if self.type_ is not Parameter.Type.NOT_SET:
            fields[names[self.type_.value - 1]] = self.value
        return SimpleNamespace(type=self.type_.value, **fields)


_SCALAR_TYPES = {bool: Parameter.Type.BOOL, int: Parameter.Type.INTEGER,
                 float: Parameter.Type.DOUBLE, str: Parameter.Type.STRING}
_ARRAY_TYPES = {bool: Parameter.Type.BOOL_ARRAY, int: Parameter.Type.INTEGER_ARRAY,
                float: Parameter.Type.DOUBLE_ARRAY, str: Parameter.Type.STRING_ARRAY}


def type_of(value: Any) -> Parameter.Type:
    """The parameter type of a Python value (TypeError for one no parameter holds)."""
    if value is None:
        return Parameter.Type.NOT_SET
    if type(value) in _SCALAR_TYPES:
        return _SCALAR_TYPES[type(value)]
    if isinstance(value, bytes):
        return Parameter.Type.BYTE_ARRAY
    if isinstance(value, list | tuple) and value and len({type(v) for v in value}) == 1:
        kind = _ARRAY_TYPES.get(type(value[0]))
        if kind is not None:
            return kind
    if isinstance(value, list | tuple) and not value:
        return Parameter.Type.STRING_ARRAY
    raise TypeError(f"no parameter type holds {value!r:.60}")


def parameter_dict_from_yaml_file(*_args: Any, **_kwargs: Any) -> Any:
    """Not offered: give a twinfleet node its parameters in the scenario's `params:`."""
    from twinfleet.rclpy.api.exceptions import NotSupportedError
    raise NotSupportedError("parameter files are not read by twinfleet nodes: set parameters in "
                            "the scenario's params:")
