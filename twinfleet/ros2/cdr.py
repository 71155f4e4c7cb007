"""ROS 2 messages as plain values: CDR encoding and decoding through rosbags' type store.

The bridge and the bag export handle messages as nested dicts keyed by ROS
field names (``{"header": {"stamp": {"sec": 1, "nanosec": 0}, "frame_id":
"map"}, ...}``), lists for sequences and arrays (``bytes`` is accepted for
``uint8``/``int8``/``byte`` sequences), and Python numbers. `RosTypes` turns
them into rosbags' message objects and CDR (little-endian, with the
encapsulation header ``00 01 00 00``) and back, and computes each type's
RIHS01 hash (`twinfleet.interfaces.typehash`). A field missing from a dict takes ROS's zero value
(0, "", empty sequence, a zero nested message), as a default-constructed ROS 2
message has.

A ``byte`` (IDL octet, 0..255) is a second place where rosbags differs from
rosidl: rosbags packs and reads a single ``byte`` field as a signed int8, so
255 cannot be written and 0xFF reads as -1. The bytes on the wire are the
same; `RosTypes` converts at the seam, so ``byte`` values are 0..255 as in
rclpy (tests/ros2/test_cdr_rclpy.py).

Decoding is also where untrusted input is checked (`decode(..., strict=True)`):
the CDR must parse to the end, and no float may be NaN or infinite.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.base import Nodetype
from rosbags.typesys.store import Typestore

from twinfleet.interfaces.typehash import rihs01, store_lookup

_NUMPY = {"int8": np.int8, "uint8": np.uint8, "byte": np.uint8, "char": np.uint8,
          "int16": np.int16, "uint16": np.uint16, "int32": np.int32, "uint32": np.uint32,
          "int64": np.int64, "uint64": np.uint64, "float32": np.float32, "float64": np.float64,
          "bool": np.bool_}
_FLOATS = ("float32", "float64")


class MessageError(ValueError):
    """A value that is not a message of the type it claims; the text says where."""


class RosTypes:
    """The ROS 2 message types a bridge knows (Jazzy's standard ones by default)."""

    def __init__(self, store: Typestore | None = None) -> None:
        self.store = store if store is not None else get_typestore(Stores.ROS2_JAZZY)
        self._hashes: dict[str, str] = {}

    def known(self, ros_type: str) -> bool:
        """True if `ros_type` (``pkg/msg/Name``) is in the store."""
        return ros_type in self.store.fielddefs

    def type_hash(self, ros_type: str) -> str:
        """The RIHS01 hash a ROS 2 node announces for `ros_type`."""
        if ros_type not in self._hashes:
            self._hashes[ros_type] = rihs01(ros_type, store_lookup(self.store))
        return self._hashes[ros_type]

    def encode(self, ros_type: str, fields: Mapping[str, Any]) -> bytes:
        """CDR of the message `fields` describe.

        Raises:
            MessageError: an unknown type or field, or a value of the wrong kind.
        """
        if not self.known(ros_type):
            raise MessageError(f"unknown ROS 2 type {ros_type}")
        message = self._build(ros_type, fields, ros_type)
        return bytes(self.store.serialize_cdr(message, ros_type, little_endian=True))

    def decode(self, ros_type: str, data: bytes, *, strict: bool = False) -> dict[str, Any]:
        """The fields of the CDR message `data`; `strict`: NaN and infinities are errors too.

        Raises:
            MessageError: `data` is not a message of `ros_type`.
        """
        if not self.known(ros_type):
            raise MessageError(f"unknown ROS 2 type {ros_type}")
        try:
            message = self.store.deserialize_cdr(data, ros_type)
        except Exception as exc:  # rosbags raises SerdeError, struct.error, IndexError, ...
            raise MessageError(f"not a {ros_type}: {exc}") from None
        value = self._plain(message)
        if strict:
            bad = _first_not_finite(value, ros_type)
            if bad is not None:
                raise MessageError(f"{bad} is not a finite number")
        return value

    def _build(self, ros_type: str, fields: Mapping[str, Any], where: str) -> Any:
        if not isinstance(fields, Mapping):
            raise MessageError(f"{where}: expected a mapping, got {type(fields).__name__}")
        defs = self.store.fielddefs[ros_type][1]
        unknown = set(fields) - {name for name, _ in defs}
        if unknown:
            raise MessageError(f"{where}: {ros_type} has no field {sorted(unknown)[0]!r}")
        values = {name: self._value(desc, fields.get(name), f"{where}.{name}")
                  for name, desc in defs}
        return self.store.types[ros_type](**values)

    def _value(self, desc: Any, value: Any, where: str) -> Any:
        kind = desc[0]
        if kind == Nodetype.NAME:
            return self._build(desc[1], value if value is not None else {}, where)
        if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
            inner, size = desc[1]
            items = value if value is not None else ([] if kind == Nodetype.SEQUENCE else
                                                     [None] * size)
            if inner[0] == Nodetype.NAME:
                return [self._value(inner, item, f"{where}[{i}]") for i, item in enumerate(items)]
            base = inner[1][0]
            if base == "string":
                return [str(v) for v in items]
            return _array(base, items, where)
        return _scalar(desc[1][0], value, where)

    def _plain(self, message: Any) -> dict[str, Any]:
        defs = self.store.fielddefs[message.__msgtype__][1]
        return {name: self._plain_value(getattr(message, name), desc) for name, desc in defs}

    def _plain_value(self, value: Any, desc: Any) -> Any:
        if hasattr(value, "__msgtype__"):
            return self._plain(value)
        if isinstance(value, np.ndarray):
            return value.tolist()
        if isinstance(value, list):
            return [self._plain_value(v, desc[1][0]) for v in value]
        if desc[0] == Nodetype.BASE and desc[1][0] == "byte":
            return value & 0xFF  # rosbags reads a byte as signed (module docstring)
        return value


def _array(base: str, items: Any, where: str) -> Any:
    if isinstance(items, bytes | bytearray):
        if base not in ("int8", "uint8", "byte", "char"):
            raise MessageError(f"{where}: bytes given for a {base} sequence")
        return np.frombuffer(bytes(items), dtype=_NUMPY[base]).copy()
    try:
        return np.array([_scalar(base, v, where) for v in items], dtype=_NUMPY[base])
    except TypeError:
        raise MessageError(f"{where}: expected a sequence of {base}") from None


def _scalar(base: str, value: Any, where: str) -> Any:
    if base == "string":
        return "" if value is None else str(value)
    if value is None:
        return False if base == "bool" else 0.0 if base in _FLOATS else 0
    if base == "bool":
        return bool(value)
    if base in _FLOATS:
        if not isinstance(value, int | float) or isinstance(value, bool):
            raise MessageError(f"{where}: expected a number, got {value!r}")
        return float(value)
    if not isinstance(value, int) or isinstance(value, bool):
        raise MessageError(f"{where}: expected an integer, got {value!r}")
    info = np.iinfo(_NUMPY[base])
    if not info.min <= value <= info.max:
        raise MessageError(f"{where}: {value} is out of range for {base}")
    return value - 256 if base == "byte" and value > 127 else value  # rosbags packs it signed


def _first_not_finite(value: Any, where: str) -> str | None:
    if isinstance(value, float):
        return None if math.isfinite(value) else where
    if isinstance(value, dict):
        for key, item in value.items():
            found = _first_not_finite(item, f"{where}.{key}")
            if found:
                return found
    elif isinstance(value, list):
        for i, item in enumerate(value):
            found = _first_not_finite(item, f"{where}[{i}]")
            if found:
                return found
    return None
