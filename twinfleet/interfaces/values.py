"""Field values of ROS 2 messages: defaults, checks, and the mutable ↔ frozen conversion.

A mutable message (`generate.RosMessage`) holds what rclpy's generated classes
hold, with lists where rosidl uses numpy or `array.array` (docs/rclpy.md):

    bool → bool        integers, char → int        float32/64 → float
    string → str       byte → bytes of length 1    arrays, sequences → list
    a nested message → its mutable class

Its frozen twin (the contract's message, `generate`) holds the same values with
tuples for lists and frozen nested messages. `Converter` does one field:
a default (new each time, as rosidl's constructor makes one) and `freeze` (checks
the value, one-line `FieldValueError` naming ``type.field``): the slow path of the
functions `codegen` writes per class, which also thaw.
"""

from __future__ import annotations

import numbers
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from twinfleet.interfaces.definitions import Container, FieldDef, FieldType

#: the values each integer type holds (a .msg char is IDL uint8)
INT_RANGES = {"int8": (-(2**7), 2**7 - 1), "uint8": (0, 2**8 - 1),
               "int16": (-(2**15), 2**15 - 1), "uint16": (0, 2**16 - 1),
               "int32": (-(2**31), 2**31 - 1), "uint32": (0, 2**32 - 1),
               "int64": (-(2**63), 2**63 - 1), "uint64": (0, 2**64 - 1),
               "char": (0, 255)}
_FLOATS = frozenset({"float32", "float64", "float128"})


class FieldValueError(ValueError):
    """A message field holds a value its type does not allow; the text names the field."""


def zero(base: str) -> Any:
    """ROS's zero value of a primitive type."""
    if base == "bool":
        return False
    if base in _FLOATS:
        return 0.0
    if base == "string":
        return ""
    if base == "byte":
        return b"\x00"
    return 0


def _primitive_default(base: str, given: Any) -> Any:
    if given is None:
        return zero(base)
    if base in _FLOATS:
        return float(given)
    if base == "byte":
        return bytes([given & 0xFF]) if isinstance(given, int) else bytes(given)
    return given


def hint(t: FieldType, frozen_of: Callable[[str], type]) -> Any:
    """The type annotation of a frozen field (the contract's schemas read it)."""
    if t.nested:
        item: Any = frozen_of(t.base)
    elif t.base == "bool":
        item = bool
    elif t.base in _FLOATS:
        item = float
    elif t.base == "string":
        item = str
    elif t.base == "byte":
        item = bytes
    else:
        item = int
    return item if t.container is Container.ONE else tuple[item, ...]


def check_primitive(base: str, bound: int, value: Any, where: str) -> Any:
    """`value` as a field of primitive type `base` holds it, or FieldValueError."""
    kind = type(value)
    if base in _FLOATS:
        if isinstance(value, numbers.Real) and kind is not bool:  # ints, numpy scalars
            return float(value)
    elif base == "bool":
        if kind is bool:
            return value
    elif base == "string":
        if kind is str:
            if bound and len(value) > bound:
                raise FieldValueError(f"{where}: {len(value)} characters, more than the bound "
                                      f"{bound}")
            return value
    elif base == "byte":
        if isinstance(value, bytes | bytearray) and len(value) == 1:
            return bytes(value)
    elif isinstance(value, numbers.Integral) and kind is not bool:
        low, high = INT_RANGES[base]
        number = int(value)
        if not low <= number <= high:
            raise FieldValueError(f"{where}: {number} is out of range for {base} "
                                  f"({low}..{high})")
        return number
    raise FieldValueError(f"{where}: expected {_expected(base)}, got {value!r}")


def _expected(base: str) -> str:
    if base in _FLOATS:
        return f"a number ({base})"
    if base == "byte":
        return "one byte (bytes of length 1)"
    return {"bool": "True or False", "string": "a str"}.get(base, f"an integer ({base})")


@dataclass(frozen=True, slots=True)
class Converter:
    """Default and freeze of one field (module docstring)."""

    field: FieldDef
    mutable_of: Callable[[str], type]  # nested type name → its mutable class

    def default(self) -> Any:
        """A new default value (a new list, a new nested message)."""
        f, t = self.field, self.field.type
        if t.nested:
            cls = self.mutable_of(t.base)
            return [cls() for _ in range(t.size)] if t.container is Container.ARRAY else (
                [] if t.container is Container.SEQUENCE else cls())
        if t.container is Container.ONE:
            return _primitive_default(t.base, f.default)
        if f.default is not None:
            return [_primitive_default(t.base, v) for v in f.default]
        return [zero(t.base)] * t.size if t.container is Container.ARRAY else []

    def freeze(self, value: Any, path: str, freeze_nested: Callable[[Any, str, str], Any]) -> Any:
        """The frozen form of `value`, checked against the field's type; `path` names the
        message in an error (``geometry_msgs/msg/Twist.linear``)."""
        t, where = self.field.type, f"{path}.{self.field.name}"
        if t.container is Container.ONE:
            if t.nested:
                return freeze_nested(value, t.base, where)
            return check_primitive(t.base, t.string_bound, value, where)
        if isinstance(value, str) or not hasattr(value, "__iter__"):
            raise FieldValueError(f"{where}: expected a sequence, got {value!r}")
        items = list(value)
        if t.container is Container.ARRAY and len(items) != t.size:
            raise FieldValueError(f"{where}: expected {t.size} values, got {len(items)}")
        if t.container is Container.SEQUENCE and t.size and len(items) > t.size:
            raise FieldValueError(f"{where}: {len(items)} values, more than the bound {t.size}")
        if t.nested:
            return tuple(freeze_nested(v, t.base, f"{where}[{i}]") for i, v in enumerate(items))
        return tuple(check_primitive(t.base, t.string_bound, v, f"{where}[{i}]")
                     for i, v in enumerate(items))

    def frozen_default(self, frozen_of: Callable[[str], type]) -> Any:
        """The default of the frozen field (immutable, so one value serves every instance)."""
        t, f = self.field.type, self.field
        if t.nested:
            nested = frozen_of(t.base)
            return tuple(nested() for _ in range(t.size)) if t.container is Container.ARRAY \
                else (() if t.container is Container.SEQUENCE else nested())
        if t.container is Container.ONE:
            return _primitive_default(t.base, f.default)
        return tuple(self.default())
