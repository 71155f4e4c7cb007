"""What a node class's code names without declaring it: the services it calls and the
handlers it schedules, read from its bytecode for `twinfleet node info`.

A service client is a ``ctx.call("/name", ...)`` whose name is a literal or a
parameter (``self.params.service``, resolved by the caller); a
one-shot timer is a ``ctx.after(delay, self.handler)`` whose target is one of
the class's handlers named in that call. Names built at run time are not seen:
the lists are what the code says plainly, which is what a reader would find
too. Every function of the class (and its bases up to `Node`) is read,
helpers and nested functions included.
"""

from __future__ import annotations

import dis
import types
from collections.abc import Iterator
from typing import Final

from twinfleet.runtime.contract.node import Node, NodeSpec

_LOADS: Final = frozenset({"LOAD_METHOD", "LOAD_ATTR"})
_REACH: Final = 16  # instructions after `ctx.after` in which its target is looked for


def _codes(cls: type) -> Iterator[types.CodeType]:
    for klass in cls.__mro__:
        if klass is Node or klass is object:
            break
        for value in vars(klass).values():
            fn = getattr(value, "__func__", value)
            if isinstance(fn, types.FunctionType):
                yield from _nested(fn.__code__)


def _nested(code: types.CodeType) -> Iterator[types.CodeType]:
    yield code
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            yield from _nested(const)


def _service_name(following: list[dis.Instruction]) -> str | None:
    """The first argument of a ``ctx.call``: a literal name, or ``params.NAME`` for a
    service named by a parameter (``ctx.call(self.params.service, ...)``)."""
    first = following[0]
    if first.opname == "LOAD_CONST" and isinstance(first.argval, str):
        return first.argval
    shape = [(i.opname, i.argval) for i in following[:2]]
    if len(following) == 3 and shape == [("LOAD_FAST", "self"), ("LOAD_ATTR", "params")] \
            and following[2].opname == "LOAD_ATTR":
        return f"params.{following[2].argval}"
    return None


def code_references(cls: type) -> tuple[list[str], list[str]]:
    """(services the class calls, handlers it schedules with ``ctx.after``), each sorted; a
    service named by a parameter is ``params.NAME``."""
    handlers = {h.method for h in NodeSpec.of(cls).handlers}
    clients: set[str] = set()
    after: set[str] = set()
    for code in _codes(cls):
        ins = list(dis.get_instructions(code))
        for k, i in enumerate(ins):
            if i.opname not in _LOADS or k + 1 >= len(ins):
                continue
            if i.argval == "call":
                name = _service_name(ins[k + 1:k + 4])
                if name is not None:
                    clients.add(name)
            elif i.argval == "after":
                target = next((j.argval for j in ins[k + 1:k + 1 + _REACH]
                               if j.opname in _LOADS and j.argval in handlers), None)
                if target is not None:
                    after.add(target)
    return sorted(clients), sorted(after)
