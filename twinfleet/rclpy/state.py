"""An rclpy node's state as a value: its instance attributes and the engine's records.

The checker snapshots `adapter.state` after each handler and sets it back before one
(`twinfleet.runtime.contract.snapshot`). Here that value is `RclpyState`: every
instance attribute of the rclpy node, encoded, and the engine's `Dynamic` part as
frozen records. Encoding keeps what the checker must compare and nothing else:

- plain values, lists, tuples, dicts, sets, numpy arrays, dataclasses: as they are;
- ROS messages (mutable, rosidl-like): their frozen contract value, thawed fresh on
  the way back (`MsgValue`);
- the framework's handles (publishers, timers, clients, groups, the node itself):
  a reference by kind and index (`HandleRef`), the same object on the way back;
- futures: numbered in the order they are met (`FutureRef`), so two states whose
  futures differ only in creation order encode alike; their records follow;
- callables: as `twinfleet.rclpy.refs` writes them.

Property expressions read attributes of the node: `RclpyState` answers them
(``monitor.inside`` reads the attribute ``inside``).
"""

from __future__ import annotations

import types
from dataclasses import dataclass
from functools import partial
from typing import Any

from twinfleet.rclpy import refs, wire
from twinfleet.rclpy.api.callback_groups import CallbackGroup
from twinfleet.rclpy.api.task import Future
from twinfleet.rclpy.entities import EntityKind, Suspended, TimerSlot, Waiting
from twinfleet.runtime.contract.messages import from_plain, to_plain
from twinfleet.runtime.contract.snapshot import restore, snapshot

Engine = Any  # twinfleet.rclpy.engine.Engine (which imports this module)

_PLAIN = frozenset({int, float, bool, str, bytes, type(None)})


@dataclass(frozen=True, slots=True)
class HandleRef:
    """A framework object of the node: kind ('node', 'publisher', 'timer', ...) and index."""

    kind: str
    index: int


@dataclass(frozen=True, slots=True)
class MsgValue:
    """A mutable ROS message, as its frozen value's plain form."""

    plain: Any

    def __getattr__(self, name: str) -> Any:  # property expressions read its fields
        value = self.plain.get(name) if isinstance(self.plain, dict) else None
        if value is None and not (isinstance(self.plain, dict) and name in self.plain):
            raise AttributeError(name)
        return from_plain(value)


@dataclass(frozen=True, slots=True)
class FrozenMsg:
    """A frozen contract message (a sample waiting for its group), in plain form."""

    plain: Any


@dataclass(frozen=True, slots=True)
class FutureRef:
    """The n-th future met while encoding a state."""

    index: int


@dataclass(frozen=True, slots=True)
class DoneFuture:
    """A completed future given to a done callback: its result."""

    result: Any


@dataclass(frozen=True, slots=True)
class FutureRecord:
    """A future: 0 pending, 1 finished, 2 cancelled; result; done callbacks."""

    status: int
    result: Any
    callbacks: tuple[Any, ...]


@dataclass(frozen=True, slots=True)
class TaskRecord:
    """A suspended coroutine callback (`entities.Suspended`) as values."""

    callback: Any
    group: int | None  # the index of the group it holds busy (0: the node's default group)
    awaiting: Any
    results: tuple[Any, ...]
    clocks: tuple[int | None, ...]
    args: bytes
    start: bytes


@dataclass(frozen=True, slots=True)
class RclpyState:
    """The state of an rclpy node (module docstring)."""

    attrs: dict[str, Any]
    timers: tuple[Any, ...]
    params: dict[str, Any]
    waiting: tuple[tuple[str, int, tuple[Any, ...]], ...]
    tasks: tuple[TaskRecord, ...]
    calls: tuple[tuple[Any, ...], ...]
    on_set: tuple[Any, ...]
    futures: tuple[FutureRecord, ...]

    def __getattr__(self, name: str) -> Any:  # property expressions: node.attribute
        attrs = object.__getattribute__(self, "attrs")
        if name in attrs:
            return attrs[name]
        raise AttributeError(name)


class _Encoder:
    def __init__(self, engine: Engine, *, done_futures: bool = False) -> None:
        self.engine = engine
        self.done_futures = done_futures
        self.futures: list[Any] = []
        self.numbers: dict[int, int] = {}

    def __call__(self, value: Any) -> Any:
        kind = type(value)
        if kind in _PLAIN:
            return value
        if kind is list:
            return [self(v) for v in value]
        if kind is tuple:
            return tuple(self(v) for v in value)
        if kind is dict:
            return {self(k): self(v) for k, v in value.items()}
        if kind is set or kind is frozenset:
            return kind(self(v) for v in value)
        ref = getattr(value, "_tf_ref", None)
        if ref is not None and not isinstance(value, type) and (handle := ref()) is not None:
            return HandleRef(*handle)
        if wire.is_ros_message(value):
            return MsgValue(to_plain(wire.freeze(value)))
        if hasattr(kind, "__message_type__"):
            return FrozenMsg(to_plain(value))
        if isinstance(value, Future):
            return self.future(value)
        if isinstance(value, CallbackGroup):
            return HandleRef("group", self.engine.group_index(value))
        if isinstance(value, types.FunctionType | types.MethodType | partial):
            return refs.encode_callable(value, self.engine.node, self)
        return value

    def future(self, fut: Any) -> Any:
        if self.done_futures:
            return DoneFuture(self(fut.result()))
        number = self.numbers.get(id(fut))
        if number is None:
            number = self.numbers[id(fut)] = len(self.futures)
            self.futures.append(fut)
        return FutureRef(number)


def capture(engine: Engine) -> RclpyState:
    """The node's state now."""
    enc = _Encoder(engine)
    node_dict = engine.node.__dict__
    attrs = {k: enc(v) for k, v in node_dict.items() if k != "_tf_engine"}
    dyn = engine.dyn
    timers = tuple(None if t is None else (t.period_ms, enc(t.callback), t.group, t.canceled,
                                           t.pending, t.destroyed) for t in dyn.timers)
    waiting = tuple((w.kind.value, w.index, tuple(enc(a) for a in w.args)) for w in dyn.waiting)
    tasks = tuple(TaskRecord(enc(t.callback), t.group, enc(t.awaiting), tuple(enc(r) for r in
                             t.results), tuple(t.clocks), t.args, t.start) for t in dyn.tasks)
    calls = tuple(tuple(enc(f) for f in c) for c in dyn.calls)
    on_set = tuple(enc(cb) for cb in dyn.on_set)
    params = {k: enc(v) for k, v in dyn.params.items()}
    records: list[FutureRecord] = []
    while len(records) < len(enc.futures):  # records may meet further futures
        fut = enc.futures[len(records)]
        status = 0 if not fut.done() else (2 if fut.cancelled() else 1)
        records.append(FutureRecord(status, enc(fut._result),
                                    tuple(enc(cb) for cb in fut._callbacks)))
    return RclpyState(attrs, timers, params, waiting, tasks, calls, on_set, tuple(records))


class _Decoder:
    def __init__(self, engine: Engine, futures: list[Any]) -> None:
        self.engine = engine
        self.futures = futures

    def __call__(self, value: Any) -> Any:
        kind = type(value)
        if kind in _PLAIN:
            return value
        if kind is list:
            return [self(v) for v in value]
        if kind is tuple:
            return tuple(self(v) for v in value)
        if kind is dict:
            return {self(k): self(v) for k, v in value.items()}
        if kind is set or kind is frozenset:
            return kind(self(v) for v in value)
        if kind is MsgValue:
            return wire.thaw(from_plain(value.plain))
        if kind is FrozenMsg:
            return from_plain(value.plain)
        if kind is HandleRef:
            return self.engine.handle(value.kind, value.index)
        if kind is FutureRef:
            return self.futures[value.index]
        if kind is DoneFuture:
            fut = Future()
            fut._result, fut._state = self(value.result), 1
            return fut
        if kind in (refs.MethodRef, refs.FunctionRef, refs.ClosureRef, refs.PartialRef):
            return refs.decode_callable(value, self.engine.node, self)
        return value


def apply_state(engine: Engine, st: RclpyState, *, fresh_dict: bool = False) -> None:
    """Put `st` into the node and its engine (a fresh attribute dict when asked)."""
    futures = [Future() for _ in st.futures]
    dec = _Decoder(engine, futures)
    for fut, rec in zip(futures, st.futures, strict=True):
        fut._state, fut._result, fut._engine = rec.status, dec(rec.result), engine
        fut._callbacks = [dec(cb) for cb in rec.callbacks]
    attrs = {k: dec(v) for k, v in st.attrs.items()}
    attrs["_tf_engine"] = engine
    if fresh_dict:
        engine.node.__dict__ = attrs
    else:
        node_dict = engine.node.__dict__
        node_dict.clear()
        node_dict.update(attrs)
    dyn = type(engine.dyn)()
    dyn.timers = [None if t is None else TimerSlot(t[0], dec(t[1]), t[2], t[3], t[4], t[5])
                  for t in st.timers]
    dyn.params = {k: dec(v) for k, v in st.params.items()}
    dyn.waiting = [Waiting(EntityKind(k), i, tuple(dec(a) for a in args))
                   for k, i, args in st.waiting]
    dyn.tasks = [Suspended(dec(t.callback), t.args, t.group, t.start, [dec(r) for r in t.results],
                           list(t.clocks), dec(t.awaiting)) for t in st.tasks]
    dyn.calls = [[dec(f) for f in c] for c in st.calls]
    dyn.on_set = [dec(cb) for cb in st.on_set]
    engine.dyn = dyn


def snapshot_state(engine: Engine) -> bytes:
    """The node's state now, as the checker's bytes."""
    return snapshot(capture(engine))


def restore_state(data: bytes) -> RclpyState:
    """A state from `snapshot_state` bytes."""
    value = restore(data)
    assert isinstance(value, RclpyState)
    return value


def encode_args(engine: Engine, args: tuple[Any, ...]) -> bytes:
    """A callback's arguments as bytes (a future argument: its result)."""
    return snapshot(_Encoder(engine, done_futures=True)(args))


def decode_args(engine: Engine, data: bytes) -> tuple[Any, ...]:
    """Fresh arguments from `encode_args` bytes."""
    return tuple(_Decoder(engine, [])(restore(data)))
