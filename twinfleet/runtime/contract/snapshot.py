"""Canonical, type-preserving encoding of node state.

The checker stores every node's state as bytes, hashes them and restores them
before each handler; the same bytes must come out for equal states, and the
restored value must have the same Python types (tuple stays tuple, a dataclass
comes back as itself). msgpack arrays are lists; tuples, dicts, sets, numpy
arrays, dataclasses and enum members travel as msgpack extension types. A dataclass whose
fields are all *declared* as plain values and tuples takes a fast path: its
arrays travel natively and come back as tuples (a value that breaks its own
declaration, a list in a tuple field, comes back as a tuple). A dataclass that sets
the class attribute ``__snapshot_flat__ = True`` takes that path whatever its hints say:
it promises values whose loose encoding is already canonical (no dict whose order may
vary) and reads every array back as a tuple (the rclpy wing's node state does).
"""

from __future__ import annotations

import dataclasses
import enum
import importlib
import types
import typing
from collections.abc import Callable
from functools import cache
from operator import attrgetter
from typing import Any

import msgpack
import numpy as np

_TUPLE, _DICT, _SET, _ARRAY, _DATACLASS, _FLAT_DATACLASS, _ENUM = 1, 2, 3, 4, 5, 6, 7
_PLAIN = (int, float, bool, str, bytes, type(None))


class SnapshotError(TypeError):
    """A state holds a value that cannot be snapshot (a lambda, a socket, ...)."""


def _default(obj: Any) -> msgpack.ExtType:
    flat = _flat(type(obj))
    if flat is not None:  # the commonest case first (node states, messages)
        return msgpack.ExtType(_FLAT_DATACLASS, _pack_loose([flat[0], flat[1](obj)]))
    if isinstance(obj, _SortedItems):
        return msgpack.ExtType(_DICT, _pack([list(kv) for kv in obj]))
    if isinstance(obj, tuple):
        return msgpack.ExtType(_TUPLE, _pack(list(obj)))
    if isinstance(obj, set | frozenset):
        return msgpack.ExtType(_SET, _pack(sorted(obj, key=_pack)))
    if isinstance(obj, np.ndarray):
        return msgpack.ExtType(_ARRAY, _pack([obj.dtype.str, list(obj.shape), obj.tobytes()]))
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        cls = type(obj)
        values = [getattr(obj, name) for name in _field_names(cls)]
        if _tuples_only(cls):
            # Fast path: every field is declared as plain values and tuples, so arrays
            # can travel natively and come back as tuples (no extension per tuple).
            return msgpack.ExtType(_FLAT_DATACLASS, _pack_loose([_class_path(cls), values]))
        return msgpack.ExtType(_DATACLASS, _pack([_class_path(cls), [_canonical(v) for v in values]]))
    if isinstance(obj, enum.Enum):  # a member, by its class and value (a StrEnum too)
        return msgpack.ExtType(_ENUM, _pack([_class_path(type(obj)), obj.value]))
    if isinstance(obj, np.generic):
        return obj.item()
    raise SnapshotError(f"cannot snapshot a value of type {type(obj).__name__}: {obj!r:.80}")


class _SortedItems(tuple[tuple[Any, Any], ...]):
    """A dict's items in canonical order (msgpack would keep insertion order)."""


def _canonical(value: Any) -> Any:
    """Replace dicts (at any depth of lists and tuples) by their sorted items."""
    kind = type(value)
    if kind is dict:
        items = ((_canonical(k), _canonical(v)) for k, v in value.items())
        return _SortedItems(sorted(items, key=lambda kv: _pack(kv[0])))
    if kind is list:
        return [_canonical(v) for v in value]
    if kind is tuple:
        return tuple(_canonical(v) for v in value)
    return value


def _pack(obj: Any) -> bytes:
    return msgpack.packb(obj, default=_default, use_bin_type=True, strict_types=True)


def _pack_loose(obj: Any) -> bytes:
    return msgpack.packb(obj, default=_default, use_bin_type=True)


@cache
def _class_path(cls: type) -> str:
    return f"{cls.__module__}:{cls.__qualname__}"


@cache
def _field_names(cls: type) -> tuple[str, ...]:
    return tuple(f.name for f in dataclasses.fields(cls))


_Flat = tuple[str, Callable[[Any], list[Any]]]
_FLAT: dict[type, _Flat | None] = {}


def _flat(cls: type) -> _Flat | None:
    """For a dataclass whose fields are all declared as plain values and tuples (the fast
    path, `_tuples_only`): its class path and a function reading its field values; else
    None. Asked for every value encoded, so answered once per type."""
    try:
        return _FLAT[cls]
    except KeyError:
        pass
    found: _Flat | None = None
    if dataclasses.is_dataclass(cls) and _tuples_only(cls):
        names = _field_names(cls)
        if len(names) >= 2:
            getter = attrgetter(*names)
            found = _class_path(cls), lambda obj: list(getter(obj))
        else:
            found = _class_path(cls), lambda obj: [getattr(obj, name) for name in names]
    _FLAT[cls] = found
    return found


@cache
def _tuples_only(cls: type) -> bool:
    """True when every field is declared as plain values, tuples of them, or Optional (or
    the class says its values are packed loosely: `__snapshot_flat__`)."""
    if cls.__dict__.get("__snapshot_flat__", False):
        return True
    try:
        hints = typing.get_type_hints(cls)
    except Exception:  # unresolvable annotations: take the general path
        return False
    return all(_plain_hint(hints.get(name)) for name in _field_names(cls))


def _plain_hint(hint: Any) -> bool:
    if hint in _PLAIN:
        return True
    origin = typing.get_origin(hint)
    if origin is tuple or origin in (typing.Union, types.UnionType):
        return all(a is Ellipsis or _plain_hint(a) for a in typing.get_args(hint))
    return False


@cache
def _class_named(path: str) -> Any:  # a class, by its module:qualname
    module, _, qualname = path.partition(":")
    obj: Any = importlib.import_module(module)
    for part in qualname.split("."):
        obj = getattr(obj, part)
    return obj


def _ext_hook(code: int, data: bytes) -> Any:
    value = _unpack_tuples(data) if code == _FLAT_DATACLASS else _unpack(data)
    if code == _TUPLE:
        return tuple(value)
    if code == _DICT:
        return {k: v for k, v in value}
    if code == _SET:
        return set(value)
    if code == _ARRAY:
        dtype, shape, raw = value
        return np.frombuffer(raw, dtype=np.dtype(dtype)).reshape(tuple(shape)).copy()
    if code in (_DATACLASS, _FLAT_DATACLASS):
        path, values = value
        cls = _class_named(path)
        obj = cls.__new__(cls)
        for name, v in zip(_field_names(cls), values, strict=True):
            object.__setattr__(obj, name, v)
        return obj
    if code == _ENUM:
        path, member = value
        return _class_named(path)(member)
    raise SnapshotError(f"unknown snapshot extension code {code}")


def _unpack(data: bytes) -> Any:
    return msgpack.unpackb(data, ext_hook=_ext_hook, use_list=True, raw=False, strict_map_key=False)


def _unpack_tuples(data: bytes) -> Any:
    return msgpack.unpackb(data, ext_hook=_ext_hook, use_list=False, raw=False, strict_map_key=False)


def snapshot(value: Any) -> bytes:
    """Encode `value` canonically (equal values give equal bytes)."""
    kind = type(value)
    if kind is tuple:  # an event's args: messages, timer arguments
        items = _flat_items(value)
        if items is not None:
            return msgpack.packb(msgpack.ExtType(_TUPLE, msgpack.packb(items, use_bin_type=True)),
                                 use_bin_type=True)
    flat = _flat(kind)
    if flat is not None:  # the bytes `_default` gives it, without the general dispatch
        return msgpack.packb(msgpack.ExtType(_FLAT_DATACLASS,
                                             _pack_loose([flat[0], flat[1](value)])),
                             use_bin_type=True)
    return _pack(_canonical(value))


def _flat_items(values: tuple[Any, ...]) -> list[Any] | None:
    """The items of a tuple as the general path packs them, if each is a flat dataclass (its
    extension) or a plain value (itself); else None."""
    items: list[Any] = []
    for v in values:
        kind = type(v)
        if kind in _PLAIN:
            items.append(v)
            continue
        flat = _flat(kind)
        if flat is None:
            return None
        items.append(msgpack.ExtType(_FLAT_DATACLASS, _pack_loose([flat[0], flat[1](v)])))
    return items


def restore(data: bytes) -> Any:
    """Decode bytes made by `snapshot` into a fresh, independent value."""
    return _unpack(data)
