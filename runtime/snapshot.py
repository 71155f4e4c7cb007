"""Canonical, type-preserving encoding of node state.

The checker stores every node's state as bytes, hashes them and restores them
before each handler; the same bytes must come out for equal states, and the
restored value must have the same Python types (tuple stays tuple, a dataclass
comes back as itself). msgpack arrays are lists; tuples, dicts, sets, numpy
arrays and dataclasses travel as msgpack extension types.
"""

from __future__ import annotations

import dataclasses
import importlib
from functools import cache
from typing import Any

import msgpack
import numpy as np

_TUPLE, _DICT, _SET, _ARRAY, _DATACLASS = 1, 2, 3, 4, 5


class SnapshotError(TypeError):
    """A state holds a value that cannot be snapshot (a lambda, a socket, ...)."""


def _default(obj: Any) -> msgpack.ExtType:
    if isinstance(obj, tuple):
        return msgpack.ExtType(_TUPLE, _pack(list(obj)))
    if isinstance(obj, dict):
        items = sorted(obj.items(), key=lambda kv: _pack(kv[0]))
        return msgpack.ExtType(_DICT, _pack([list(kv) for kv in items]))
    if isinstance(obj, set | frozenset):
        return msgpack.ExtType(_SET, _pack(sorted(obj, key=_pack)))
    if isinstance(obj, np.ndarray):
        return msgpack.ExtType(_ARRAY, _pack([obj.dtype.str, list(obj.shape), obj.tobytes()]))
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        cls = type(obj)
        values = tuple(getattr(obj, f.name) for f in dataclasses.fields(obj))
        return msgpack.ExtType(_DATACLASS, _pack([f"{cls.__module__}:{cls.__qualname__}", list(values)]))
    if isinstance(obj, np.generic):
        return obj.item()
    raise SnapshotError(f"cannot snapshot a value of type {type(obj).__name__}: {obj!r:.80}")


def _pack(obj: Any) -> bytes:
    return msgpack.packb(obj, default=_default, use_bin_type=True, strict_types=True)


@cache
def _class_named(path: str) -> type:
    module, _, qualname = path.partition(":")
    obj: Any = importlib.import_module(module)
    for part in qualname.split("."):
        obj = getattr(obj, part)
    return obj


def _ext_hook(code: int, data: bytes) -> Any:
    value = _unpack(data)
    if code == _TUPLE:
        return tuple(value)
    if code == _DICT:
        return {k: v for k, v in value}
    if code == _SET:
        return set(value)
    if code == _ARRAY:
        dtype, shape, raw = value
        return np.frombuffer(raw, dtype=np.dtype(dtype)).reshape(tuple(shape)).copy()
    if code == _DATACLASS:
        path, values = value
        cls = _class_named(path)
        obj = cls.__new__(cls)
        for f, v in zip(dataclasses.fields(cls), values, strict=True):
            object.__setattr__(obj, f.name, v)
        return obj
    raise SnapshotError(f"unknown snapshot extension code {code}")


def _unpack(data: bytes) -> Any:
    return msgpack.unpackb(data, ext_hook=_ext_hook, use_list=True, raw=False, strict_map_key=False)


def snapshot(value: Any) -> bytes:
    """Encode `value` canonically (equal values give equal bytes)."""
    return _pack(value)


def restore(data: bytes) -> Any:
    """Decode bytes made by `snapshot` into a fresh, independent value."""
    return _unpack(data)
