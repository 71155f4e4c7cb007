"""Callables as state: the callbacks an rclpy node keeps (timers made at run time, done
callbacks of futures, on-set-parameter callbacks) written as plain values and built again.

The checker stores node states as bytes (`twinfleet.runtime.contract.snapshot`), so a
callback that lives in a state must be a value. Four shapes are enough for rclpy code:

- a method of the node (``self.on_reply``): its name;
- a function of a module (``on_reply``, a ``functools.partial`` of one): where it lives;
- a lambda or a closure (``lambda f: self.done(f, i)``): the function that defines it, the
  line it starts on and the values its free variables hold, encoded like any state value.
  It is built again from its code object with new cells (the code object is found among
  the constants of its defining function, so any process that imported the module can);
- ``functools.partial`` of any of these with encodable arguments.

Encoding a value that may hold the node or other handles is the caller's job: the
`encode`/`decode` functions passed in (`twinfleet.rclpy.state`).
"""

from __future__ import annotations

import functools
import importlib
import types
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

Encode = Callable[[Any], Any]
Decode = Callable[[Any], Any]


class CallbackError(TypeError):
    """A callback cannot be kept in a state (a builtin, a C function, a generator...)."""


@dataclass(frozen=True, slots=True)
class MethodRef:
    """A method of the node, by name."""

    name: str


@dataclass(frozen=True, slots=True)
class FunctionRef:
    """A function reachable as ``module:qualname``."""

    module: str
    qualname: str


@dataclass(frozen=True, slots=True)
class ClosureRef:
    """A lambda or nested function: its defining code, first line and captured values."""

    module: str
    outer: str  # qualname of the function whose constants hold the code
    name: str
    line: int
    cells: tuple[Any, ...]
    defaults: tuple[Any, ...]


@dataclass(frozen=True, slots=True)
class PartialRef:
    """``functools.partial(func, *args, **kwargs)``."""

    func: Any
    args: tuple[Any, ...]
    kwargs: tuple[tuple[str, Any], ...]


def encode_callable(fn: Any, node: object, encode: Encode, *, bare: bool = False) -> Any:
    """The value that stands for `fn` in a state (see the module docstring); with `bare`,
    a method of the node is its name alone (where nothing but callbacks is kept)."""
    if bare and isinstance(fn, types.MethodType) and fn.__self__ is node:
        return fn.__func__.__name__
    if isinstance(fn, functools.partial):
        return PartialRef(encode_callable(fn.func, node, encode), tuple(encode(a) for a in fn.args),
                          tuple(sorted((k, encode(v)) for k, v in fn.keywords.items())))
    if isinstance(fn, types.MethodType):
        if fn.__self__ is node:
            return MethodRef(fn.__func__.__name__)
        raise CallbackError(f"callback {fn!r:.60} is a method of another object than the node")
    if not isinstance(fn, types.FunctionType):
        raise CallbackError(f"callback {fn!r:.60} is not a Python function or method")
    qualname = fn.__qualname__
    if "<locals>" not in qualname and fn.__closure__ is None:
        return FunctionRef(fn.__module__, qualname)
    outer = qualname.rsplit(".<locals>.", 1)[0]
    cells = tuple(encode(c.cell_contents) for c in fn.__closure__ or ())
    return ClosureRef(fn.__module__, outer, fn.__code__.co_name, fn.__code__.co_firstlineno,
                      cells, tuple(encode(d) for d in fn.__defaults__ or ()))


def decode_callable(ref: Any, node: object, decode: Decode) -> Callable[..., Any]:
    """The callable `ref` stands for, bound to `node` where it names a method (a bare
    name too)."""
    if isinstance(ref, str):
        return getattr(node, ref)
    if isinstance(ref, MethodRef):
        return getattr(node, ref.name)
    if isinstance(ref, PartialRef):
        return functools.partial(decode_callable(ref.func, node, decode),
                                 *(decode(a) for a in ref.args),
                                 **{k: decode(v) for k, v in ref.kwargs})
    if isinstance(ref, FunctionRef):
        return _lookup(ref.module, ref.qualname)
    if isinstance(ref, ClosureRef):
        code = _closure_code(ref.module, ref.outer, ref.name, ref.line)
        module = importlib.import_module(ref.module)
        cells = tuple(types.CellType(decode(v)) for v in ref.cells)
        fn = types.FunctionType(code, vars(module), ref.name, tuple(decode(d) for d in ref.defaults)
                                or None, cells or None)
        return fn
    raise CallbackError(f"not a callback reference: {ref!r:.60}")


def _lookup(module: str, qualname: str) -> Any:
    obj: Any = importlib.import_module(module)
    for part in qualname.split("."):
        obj = getattr(obj, part)
    return obj


@functools.cache
def _closure_code(module: str, outer: str, name: str, line: int) -> types.CodeType:
    """The code object of a nested function, searched in the constants of its definer."""
    parts = outer.split(".<locals>.")
    owner = _lookup(module, parts[0])
    code: types.CodeType = getattr(owner, "__func__", owner).__code__
    for inner in parts[1:]:
        code = _find_code(code, inner.rsplit(".", 1)[-1], None)
    return _find_code(code, name, line)


def _find_code(code: types.CodeType, name: str, line: int | None) -> types.CodeType:
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            if const.co_name == name and (line is None or const.co_firstlineno == line):
                return const
            try:
                return _find_code(const, name, line)
            except CallbackError:
                continue
    raise CallbackError(f"no function {name!r} (line {line}) inside {code.co_name}")
