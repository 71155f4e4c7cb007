"""An rclpy node's state as a value: its instance attributes and the engine's records.

The checker snapshots `adapter.state` after each handler and sets it back before one
(`twinfleet.runtime.contract.snapshot`). Here that value is `RclpyState`: every
instance attribute of the rclpy node, encoded, and the engine's `Dynamic` part as
frozen records. Encoding keeps what the checker must compare and nothing else:

- plain values, lists, tuples, dicts, sets, numpy arrays, dataclasses: as they are;
- ROS messages (mutable, rosidl-like): their frozen contract value, as msgpack bytes of
  its plain form, thawed fresh on the way back (`MsgValue`);
- the framework's handles (publishers, timers, clients, groups, the node itself): not
  state; an attribute that holds one is listed by name, kind and index (`handles`), and
  one inside a value is a `HandleRef`; the same object comes back;
- futures: numbered in the order they are met (`FutureRef`), so two states whose
  futures differ only in creation order encode alike; their records follow;
- callables: as `twinfleet.rclpy.refs` writes them.

The checker encodes a state after every handler, so `RclpyState` takes the snapshot's
flat path (`__snapshot_flat__`): its records are plain values built in a fixed order,
packed as they are, and every array comes back as a tuple. A user's lists therefore
stay plain arrays (read back as lists), while a user's tuples and dicts are wrapped
(`TupleValue`, `DictValue`, a dict with its items sorted) so that the difference and
a canonical order survive.

Property expressions read attributes of the node: `RclpyState` answers them
(``monitor.inside`` reads the attribute ``inside``).
"""

from __future__ import annotations

import functools
import types
from collections.abc import Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any, ClassVar

import msgpack

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
    """A framework object of the node inside a value: kind ('publisher', 'timer', ...), index."""

    kind: str
    index: int


def _pack_message(frozen: Any) -> bytes:
    # to_plain lists fields in declaration order: equal messages give equal bytes
    return msgpack.packb(to_plain(frozen), use_bin_type=True)


def _unpack_message(data: bytes) -> Any:
    return from_plain(msgpack.unpackb(data, raw=False))


@dataclass(frozen=True, slots=True)
class MsgValue:
    """A mutable ROS message: the msgpack bytes of its frozen value's plain form (the name
    ends in ``_`` so that it never hides a field of the message: ``last.data``)."""

    packed_: bytes

    def __getattr__(self, name: str) -> Any:  # property expressions read its fields
        return getattr(_unpack_message(object.__getattribute__(self, "packed_")), name)


@dataclass(frozen=True, slots=True)
class TupleValue:
    """A user's tuple (arrays of the flat encoding read back as lists)."""

    items: tuple[Any, ...]


@dataclass(frozen=True, slots=True)
class DictValue:
    """A user's dict, its items sorted by the encoded key."""

    items: tuple[Any, ...]


@dataclass(frozen=True, slots=True)
class FutureRef:
    """The n-th future met while encoding a state."""

    index: int


@dataclass(frozen=True, slots=True)
class DoneFuture:
    """A completed future given to a done callback: its result."""

    result: Any


@dataclass(frozen=True, slots=True)
class RclpyState:
    """The state of an rclpy node (module docstring).

    Attributes:
        attrs: ``[name, value]`` of the node's instance attributes but its handles, encoded,
            sorted by name.
        handles: ``name=kind:index`` for each attribute that holds a handle, sorted.
        timers: per timer slot ``[period_ms, callback, group, canceled, pending, destroyed]``
            (None: a free slot).
        params: ``[name, value]`` of each declared parameter, sorted by name.
        waiting: ``[kind, index, [sample]]`` of each callback held back by its group (a sample
            as the plain form of the frozen message; a request with its `ReplyToken`).
        tasks: each suspended coroutine callback: ``callback``, ``group`` (held busy),
            ``awaiting`` (a future's number), ``results`` and ``clocks`` of its steps so
            far, ``args`` and ``start`` (snapshot bytes of the state it began in), ``reply``
            (a service callback's `ReplyToken`, else None).
        calls: per client, per call slot, the number of the future of the call waiting for
            its reply there (-1: a free slot).
        on_set: the on-set-parameters callbacks.
        futures: per future ``[status (0 pending, 1 done, 2 cancelled), result, callbacks]``.
    """

    __snapshot_flat__: ClassVar[bool] = True

    attrs: Sequence[Any]
    handles: str
    timers: Sequence[Any]
    params: Sequence[Any]
    waiting: Sequence[Any]
    tasks: Sequence[Any]
    calls: Sequence[Any]
    on_set: Sequence[Any]
    futures: Sequence[Any]

    def __repr__(self) -> str:
        """The node's attributes first, as a person reads them (a live violation's report
        shows the first few hundred characters), then what its executor holds, if any."""
        parts = [", ".join(f"{key}={plain_view(value)!r}" for key, value in self.attrs)]
        held = (("timers", self.timers), ("waiting", self.waiting), ("tasks", self.tasks),
                ("calls", [c for c in self.calls if c]))
        parts += [f"{name}={list(value)!r}" for name, value in held if value]
        return f"rclpy node({'; '.join(parts)})"

    def __getattr__(self, name: str) -> Any:  # property expressions: node.attribute
        for key, value in object.__getattribute__(self, "attrs"):
            if key == name:
                return plain_view(value)
        raise AttributeError(name)


def plain_view(value: Any) -> Any:
    """An encoded attribute as the node had it (lists, tuples and dicts again); messages,
    handles and futures stay as their encoded stand-ins (fields of a message read through)."""
    kind = type(value)
    if kind is tuple or kind is list:
        return [plain_view(v) for v in value]
    if kind is TupleValue:
        return tuple(plain_view(v) for v in value.items)
    if kind is DictValue:
        return {plain_view(k): plain_view(v) for k, v in value.items}
    return value


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
            return TupleValue(tuple(self(v) for v in value))
        if kind is dict:
            items = ((self(k), self(v)) for k, v in value.items())
            return DictValue(tuple(sorted(items, key=lambda kv: snapshot(kv[0]))))
        if kind is set or kind is frozenset:
            return kind(self(v) for v in value)
        handle = _handle(value)
        if handle is not None:
            return HandleRef(*handle)
        if wire.is_ros_message(value):
            return MsgValue(_pack_message(wire.freeze(value)))
        if isinstance(value, Future):
            return self.future(value) if not self.done_futures else DoneFuture(
                self(value.result()))
        if isinstance(value, CallbackGroup):
            return HandleRef("group", self.engine.group_index(value))
        if isinstance(value, types.FunctionType | types.MethodType | partial):
            return refs.encode_callable(value, self.engine.node, self)
        return value

    def callback(self, fn: Any) -> Any:
        """A callback where only callbacks go: a method of the node is its bare name."""
        return refs.encode_callable(fn, self.engine.node, self, bare=True)

    def future(self, fut: Any) -> FutureRef:
        number = self.numbers.get(id(fut))
        if number is None:
            number = self.numbers[id(fut)] = len(self.futures)
            self.futures.append(fut)
        return FutureRef(number)


def _handle(value: Any) -> tuple[str, int] | None:
    ref = getattr(value, "_tf_ref", None)
    if ref is None or isinstance(value, type):
        return None
    return ref()


def _timer_record(enc: _Encoder, slot: TimerSlot) -> Any:
    """A timer as one readable line when its callback is a method of the node (the usual
    case: one string is cheaper to encode than a list), else as a list."""
    if slot.ref is None:
        slot.ref = enc.callback(slot.callback)
    if type(slot.ref) is not str:
        return [slot.period_ms, slot.ref, slot.group, slot.canceled, slot.pending,
                slot.destroyed]
    return _timer_line(slot.period_ms, slot.ref, slot.group, slot.canceled, slot.pending,
                       slot.destroyed)


@functools.lru_cache(maxsize=1024)
def _timer_line(period_ms: int, ref: str, group: int, canceled: bool, pending: int,
                destroyed: bool) -> str:
    flags = "".join(f" {flag}" for flag, on in (("canceled", canceled),
                                                ("destroyed", destroyed)) if on)
    return f"every {period_ms} ms: {ref} (group {group}), {pending} firing(s) scheduled{flags}"


def _timer_slot(dec: _Decoder, record: Any) -> TimerSlot:
    if type(record) is not str:
        period, ref, group, canceled, pending, destroyed = record
        return TimerSlot(period, dec.callback(ref), group, canceled, pending, destroyed, ref)
    period, ref, group, canceled, pending, destroyed = _parse_timer_line(record)
    return TimerSlot(period, dec.callback(ref), group, canceled, pending, destroyed, ref)


@functools.lru_cache(maxsize=1024)
def _parse_timer_line(line: str) -> tuple[int, str, int, bool, int, bool]:
    words = line.split()
    return (int(words[1]), words[3], int(words[5].rstrip("),")), "canceled" in words[7:],
            int(words[6]), "destroyed" in words[7:])


def capture(engine: Engine) -> RclpyState:
    """The node's state now."""
    enc = _Encoder(engine)
    attrs: list[Any] = []
    handles: list[str] = []
    node_dict = engine.node.__dict__
    for key in sorted(node_dict):
        value = node_dict[key]
        if type(value) in _PLAIN:
            attrs.append([key, value])
            continue
        if key == "_tf_engine":
            continue
        named = getattr(value, "_tf_key", None)
        if named is not None:
            handles.append(f"{key}={named}")
            continue
        handle = _handle(value)
        if handle is None:
            attrs.append([key, enc(value)])
        else:
            handles.append(f"{key}={handle[0]}:{handle[1]}")
    # The records are tuples, as the flat encoding reads them back: a state set back that
    # equals the one just captured is then found equal, and the engine's part is kept.
    dyn = engine.dyn
    timers = tuple(None if t is None else _timer_record(enc, t) for t in dyn.timers)
    # a waiting sample as its plain form (fields in declaration order: canonical as it is)
    waiting = tuple((w.kind.value, w.index, tuple(to_plain(a) for a in w.args))
                    for w in dyn.waiting)
    tasks = tuple({"callback": enc.callback(t.callback), "group": t.group,
                   "awaiting": enc.future(t.awaiting).index,
                   "results": tuple(enc(r) for r in t.results), "clocks": tuple(t.clocks),
                   "args": t.args, "start": t.start, "reply": t.reply} for t in dyn.tasks)
    calls = tuple(tuple(-1 if f is None else enc.future(f).index for f in c) for c in dyn.calls)
    on_set = tuple(enc.callback(cb) for cb in dyn.on_set)
    params = tuple((k, enc(dyn.params[k])) for k in sorted(dyn.params))
    records: list[Any] = []
    while len(records) < len(enc.futures):  # records may meet further futures
        fut = enc.futures[len(records)]
        status = 0 if not fut.done() else (2 if fut.cancelled() else 1)
        records.append((status, enc(fut._result), tuple(enc.callback(cb)
                                                          for cb in fut._callbacks)))
    engine.synced = None if records else (timers, params, waiting, tasks, calls, on_set)
    return RclpyState(tuple(attrs), " ".join(handles), timers, params, waiting, tasks, calls,
                      on_set, tuple(records))


class _Decoder:
    def __init__(self, engine: Engine, futures: list[Any]) -> None:
        self.engine = engine
        self.futures = futures

    def __call__(self, value: Any) -> Any:
        kind = type(value)
        if kind in _PLAIN:
            return value
        if kind is list or kind is tuple:  # the flat encoding reads arrays back as tuples
            return [self(v) for v in value]
        if kind is TupleValue:
            return tuple(self(v) for v in value.items)
        if kind is DictValue:
            return {self(k): self(v) for k, v in value.items}
        if kind is set or kind is frozenset:
            return kind(self(v) for v in value)
        if kind is MsgValue:
            return wire.thaw(_unpack_message(value.packed_))
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

    def callback(self, ref: Any) -> Any:
        return refs.decode_callable(ref, self.engine.node, self)


@functools.lru_cache(maxsize=256)
def _handle_list(handles: str) -> tuple[tuple[str, str, int], ...]:
    out = []
    for item in handles.split():
        key, _, ref = item.partition("=")
        kind, _, index = ref.partition(":")
        out.append((key, kind, int(index)))
    return tuple(out)


def apply_state(engine: Engine, st: RclpyState, *, fresh_dict: bool = False) -> None:
    """Put `st` into the node and its engine (a fresh attribute dict when asked)."""
    futures = [Future() for _ in st.futures]
    dec = _Decoder(engine, futures)
    for fut, (status, result, callbacks) in zip(futures, st.futures, strict=True):
        fut._state, fut._result, fut._engine = status, dec(result), engine
        fut._callbacks = [dec.callback(cb) for cb in callbacks]
    attrs = {k: dec(v) for k, v in st.attrs}
    for key, kind, index in _handle_list(st.handles):
        attrs[key] = engine.handle(kind, index)
    attrs["_tf_engine"] = engine
    if fresh_dict:
        engine.node.__dict__ = attrs
    else:
        node_dict = engine.node.__dict__
        node_dict.clear()
        node_dict.update(attrs)
    records = (st.timers, st.params, st.waiting, st.tasks, st.calls, st.on_set)
    if not st.futures and not fresh_dict and engine.synced == records:
        return  # the engine's part is the one captured last, untouched since
    dyn = type(engine.dyn)()
    dyn.timers = [None if t is None else _timer_slot(dec, t) for t in st.timers]
    dyn.params = {k: dec(v) for k, v in st.params}
    dyn.waiting = [Waiting(EntityKind(k), i, tuple(from_plain(a) for a in args))
                   for k, i, args in st.waiting]
    dyn.tasks = [Suspended(dec.callback(t["callback"]), t["args"], t["group"], t["start"],
                           [dec(r) for r in t["results"]], list(t["clocks"]),
                           futures[t["awaiting"]], t["reply"]) for t in st.tasks]
    dyn.calls = [[None if n < 0 else futures[n] for n in c] for c in st.calls]
    dyn.on_set = [dec.callback(cb) for cb in st.on_set]
    engine.dyn = dyn
    engine.synced = None if st.futures or fresh_dict else records


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
    return tuple(_Decoder(engine, [])(restore(data)))  # a TupleValue: decoded as a tuple
