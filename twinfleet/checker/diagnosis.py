"""Diagnosing a node that breaks the node contract: what it did, where, and how to fix it.

The checker's verdicts rest on one promise of the node contract: a handler's
outcome (new node state, effects, reply) depends only on the node state, the
event, the time and the answers `ctx.choose` got. A node that reads a clock
or `random`, or keeps state outside `self.state`, breaks it, and then a
verdict means nothing (the search merges worlds that differ, a trace does not
replay). Two cheap checks run in every search, by default:

- **Environment probe.** While a handler runs, the clocks and random sources
  of the standard library (`time.time`, `time.monotonic`, `time.sleep`,
  `random.random` and every other function of the module's shared generator,
  `os.urandom`, `uuid.uuid1`/`uuid4`, `secrets`, `numpy.random`) are wrapped so that a call
  from the handler's thread is recorded (the real function still answers).
  Installed only around the handler call, so nothing else sees the wrappers.
  It names the function, so the fix is exact; it cannot see a name bound
  before the probe was installed (``from time import time``).
- **Re-execution.** Every *new* handler run (a cache miss of
  `checker.system`: a (node state, event, time) not seen before) runs a second
  time from the same state with the same choices, and the two runs are
  compared (`Runner`); the node's attributes other than `state` are also
  compared by identity before and after. This catches what the probe cannot
  see: a bound `random`/`time` function, `datetime.now()`, a counter in a module
  or class variable or in another attribute of the node.
- **Scope watch.** The module and class variables of the node's own code (the
  modules defining its class and bases, and those classes) are compared before
  and after each run (`ScopeWatch`): a counter a handler bumps but only another
  handler reads changes nothing in a re-execution, yet it is state.

Both report a `Failure` of a contract kind (`CONTRACT_KINDS`); `checker.driver`
turns it into the verdict "contract breach" (exit code 4), never a property
violation. `describe_difference` says what differed between two runs, and
`breach_line` is the one-line report naming node, handler, what happened and
the fix.
"""

from __future__ import annotations

import dataclasses
import operator
import os
import random
import secrets
import sys
import threading
import time
import uuid
from collections.abc import Callable, Sequence
from types import ModuleType
from typing import Any, final

import numpy as np

from twinfleet.runtime.contract.kinds import FailureKind
from twinfleet.runtime.contract.snapshot import SnapshotError, restore

#: Failure kinds that mean "the node breaks the contract" rather than "a property fails".
CONTRACT_KINDS = frozenset({FailureKind.NONDETERMINISM, FailureKind.STATE_OUTSIDE,
                            FailureKind.CONTRACT})

_CLOCKS = ("time", "time_ns", "monotonic", "monotonic_ns", "perf_counter", "perf_counter_ns",
           "process_time", "process_time_ns", "thread_time", "thread_time_ns", "localtime",
           "gmtime", "ctime", "asctime", "sleep")
_RANDOM = tuple(name for name in random.__all__
                if getattr(getattr(random, name, None), "__self__", None) is random._inst)
_NUMPY_RANDOM = ("random", "rand", "randn", "randint", "random_sample", "choice", "shuffle",
                 "permutation", "uniform", "normal", "default_rng")
_SECRETS = ("token_bytes", "token_hex", "token_urlsafe", "randbelow", "randbits", "choice")

FIX_RANDOM = ("take random decisions with ctx.choose(options): live it picks one, the checker "
              "explores every option")
FIX_CLOCK = "read time with ctx.now() (ms since the fleet's start, the same in both drivers)"
FIX_SLEEP = "never block in a handler: schedule the rest with ctx.after(ms, self.method, *args)"
FIX_STATE = ("keep everything a handler changes in self.state (not in module or class "
             "variables, nor in other attributes of the node)")
FIX_CONTEXT = ("pass ctx.after and ctx.call a method of the node (a @handler) and its "
               "arguments as hashable plain values, never a lambda or a closure")
FIX_ENCODABLE = ("self.state may hold only plain values: int, float, bool, str, bytes, None, "
                 "tuples, lists, dicts and sets of those, dataclasses and numpy arrays")
FIX_HIDDEN = ("make the handler depend only on self.state, the message and ctx: no clocks, "
              "no random, no module-level or class-level counters, no other attributes of "
              "self that change")


def _fix_for(function: str) -> str:
    if function == "time.sleep":
        return FIX_SLEEP
    return FIX_CLOCK if function.startswith("time.") else FIX_RANDOM


@final
class EnvironmentProbe:
    """Records calls to clocks and random sources made by the thread that runs a handler.

    Use as a context manager around one handler call; `calls` lists the functions
    called (``"random.random"``), in order, without repeats.
    """

    def __init__(self) -> None:
        self.calls: list[str] = []
        self._owner: int | None = None
        # Per module namespace: the wrapped functions and the originals, swapped in and out
        # with one `dict.update` each (a handler run installs and removes ~60 of them).
        self._patches: list[tuple[dict[str, Any], dict[str, Any], dict[str, Any]]] = []
        for module, label, names in _sources():
            originals = {name: original for name in names
                         if callable(original := getattr(module, name, None))}
            probed = {name: self._wrap(f"{label}.{name}", original)
                      for name, original in originals.items()}
            self._patches.append((vars(module), probed, originals))

    def _wrap(self, label: str, original: Callable[..., Any]) -> Callable[..., Any]:
        def probed(*args: Any, **kwargs: Any) -> Any:
            if self._owner == threading.get_ident() and label not in self.calls:
                self.calls.append(label)
            return original(*args, **kwargs)
        return probed

    def __enter__(self) -> EnvironmentProbe:
        self.calls = []
        self._owner = threading.get_ident()
        for namespace, probed, _ in self._patches:
            namespace.update(probed)
        return self

    def __exit__(self, *exc: object) -> None:
        for namespace, _, originals in self._patches:
            namespace.update(originals)
        self._owner = None


def _sources() -> list[tuple[ModuleType, str, Sequence[str]]]:
    return [(time, "time", _CLOCKS), (random, "random", _RANDOM), (os, "os", ("urandom",)),
            (uuid, "uuid", ("uuid1", "uuid4")), (secrets, "secrets", _SECRETS),
            (np.random, "numpy.random", _NUMPY_RANDOM)]


_SMALL = 64  # mutable module/class containers up to this size are compared by content


@final
class ScopeWatch:
    """The module and class variables a node class's code could keep state in.

    The data (not functions, classes or modules) in the modules that define the
    class and its bases, and in those classes' own namespaces, below `Node`: `take`
    records them (identity, and the contents of small lists, dicts, sets and
    bytearrays) and `changed` names those a handler rebound or changed in place.
    """

    def __init__(self, cls: type) -> None:
        spaces: dict[int, tuple[str, Any]] = {}
        for klass in cls.__mro__:
            if klass is object or klass.__module__.startswith("twinfleet.runtime"):
                continue
            module = sys.modules.get(klass.__module__)
            if module is not None:
                spaces.setdefault(id(module), (module.__name__, vars(module)))
            spaces.setdefault(id(klass), (klass.__qualname__, klass.__dict__))
        self._spaces = list(spaces.values())
        self._keys = [(label, space, key) for label, space in self._spaces
                      for key, value in list(space.items()) if _is_data(key, value)]
        self._small = [(label, space, key) for label, space, key in self._keys
                       if type(space[key]) in _MUTABLE and len(space[key]) <= _SMALL]

    def take(self) -> tuple[list[int], list[Any], list[Any]]:
        """What the variables hold now (cheap: identities, and copies of small containers)."""
        return ([len(space) for _, space in self._spaces],
                [space.get(key) for _, space, key in self._keys],
                [_copy(space.get(key)) for _, space, key in self._small])

    def changed(self, before: tuple[list[int], list[Any], list[Any]]) -> list[str]:
        """The variables (``module.NAME``, ``Class.NAME``) that differ from `before`."""
        sizes, held, contents = before
        now_sizes, now_held, now_contents = self.take()
        if sizes == now_sizes and all(map(operator.is_, held, now_held)) and \
                contents == now_contents:
            return []
        out = [f"{label}.{key}" for (label, _, key), a, b in
               zip(self._keys, held, now_held, strict=True) if a is not b]
        out += [f"{label}.{key}" for (label, _, key), a, b in
                zip(self._small, contents, now_contents, strict=True) if a != b]
        out += [f"a new variable in {label}" for (label, _), a, b in
                zip(self._spaces, sizes, now_sizes, strict=True) if a != b]
        return list(dict.fromkeys(out))


_MUTABLE = (list, dict, set, bytearray)


def _is_data(key: str, value: Any) -> bool:
    return not (key.startswith("__") or callable(value) or
                isinstance(value, ModuleType | property | staticmethod | classmethod))


def _copy(value: Any) -> Any:
    return value.copy() if type(value) in _MUTABLE else value


def environment_message(calls: Sequence[str]) -> str:
    """What a handler that called `calls` did wrong, and the fix."""
    fixes = dict.fromkeys(_fix_for(c) for c in calls)
    return (f"it called {', '.join(c + '()' for c in calls)}, which the checker cannot "
            f"explore or repeat; fix: {'; '.join(fixes)}")


def describe_difference(first: tuple[Any, ...], second: tuple[Any, ...]) -> str:
    """What differs between two runs: each is (state bytes, events, failure text, choices)."""
    s1, e1, f1, c1 = first
    s2, e2, f2, c2 = second
    if c1 != c2:
        return f"ctx.choose was asked different questions (answers {list(c1)} then {list(c2)})"
    if f1 != f2:
        return f"the first run {f1 or 'succeeded'}, the second {f2 or 'succeeded'}"
    if s1 != s2:
        return "the new node state differs: " + _state_difference(s1, s2)
    return "the effects differ: " + _effects_difference(e1, e2)


def _state_difference(a: bytes, b: bytes) -> str:
    try:
        x, y = restore(a), restore(b)
    except SnapshotError:
        return "(the states cannot be decoded)"
    if dataclasses.is_dataclass(x) and type(x) is type(y):
        diffs = [f"{f.name} = {getattr(x, f.name)!r:.40} then {getattr(y, f.name)!r:.40}"
                 for f in dataclasses.fields(x) if getattr(x, f.name) != getattr(y, f.name)]
        if diffs:
            return "self.state." + ", self.state.".join(diffs[:3])
    return f"{x!r:.60} then {y!r:.60}"


def _effects_difference(a: Sequence[Any], b: Sequence[Any]) -> str:
    if len(a) != len(b):
        return f"{len(a)} events sent, then {len(b)}"
    for x, y in zip(a, b, strict=True):
        if x.sk != y.sk or x.deadline != y.deadline:
            return (f"{x.kind} {x.method}{_args(x.args)} at t={x.due} then "
                    f"{y.kind} {y.method}{_args(y.args)} at t={y.due}")
    return "the logs differ"


def _args(args: tuple[Any, ...]) -> str:
    return "(" + ", ".join(f"{a!r:.30}" for a in args) + ")"


class ContractBreachError(RuntimeError):
    """The search met a contract breach the verification of single runs did not see
    (e.g. a recorded path that does not run again); its text is the one-line report."""


def breach_line(kind: FailureKind, node: str, handler: str, message: str) -> str:
    """The one-line report of a contract breach."""
    where = f"node {node}, handler {handler}" if node else f"handler {handler}"
    return f"contract breach ({kind}) in {where}: {message}"
