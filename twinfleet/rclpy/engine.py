"""The engine behind one rclpy node: rclpy's executor rules as one contract handler's work.

Each event the contract delivers to the adapter (a timer firing, a sample, a request, a
reply) becomes a ready callback of one entity. It runs at once unless its callback
group is busy; then it waits (`Waiting`) until the group frees. A coroutine callback
runs until its first `await` of a pending future and is then suspended (`Suspended`),
holding a mutually exclusive group busy, as rclpy's executor holds it while the task
is not done. When the future completes (a reply arrives), its done callbacks run and
each coroutine awaiting it resumes (`twinfleet.rclpy.tasks`); when groups free up,
waiting callbacks run, in every order the checker can choose (`ctx.choose`): the
order rclpy takes ready callbacks of one wait set in is not a documented promise.

Everything the engine changes lives in `Dynamic` and in the node's own attributes,
which together are the adapter's `state` (`twinfleet.rclpy.state`).
"""

from __future__ import annotations

import threading
import time as _time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, SupportsIndex

from twinfleet.rclpy import current, wire
from twinfleet.rclpy.entities import (
    ClientEntry,
    Dynamic,
    EntityKind,
    PublisherEntry,
    ServiceEntry,
    SubscriptionEntry,
    TimerSlot,
    Waiting,
)
from twinfleet.rclpy.tasks import DEFERRED, Tasks
from twinfleet.runtime.contract.context import Context, ContractError
from twinfleet.runtime.contract.messages import CallError

#: How long a `call_async` waits for its reply: rclpy's own calls never time out.
CALL_TIMEOUT_MS = 3_600_000

#: How many calls of one client may wait for replies at once: each has a reply handler of
#: its own (`reply_method`), so that a reply completes the future of the call it answers.
CALL_SLOTS = 8


def reply_method(client: int, slot: int) -> str:
    """The adapter's handler for replies to call slot `slot` of client `client`."""
    return f"reply_{client}" if slot == 0 else f"reply_{client}_{slot}"


@dataclass
class Construction:
    """What the loader says about the node being built: the `--ros-args` of a launch."""

    name: str | None = None
    namespace: str | None = None
    overrides: dict[str, Any] = field(default_factory=dict)
    adapter: Any = None  # the contract node that carries this rclpy node


_BUILDING: list[Construction] = []


@contextmanager
def building(construction: Construction) -> Iterator[None]:
    """Nodes constructed inside take their name, namespace and parameters from it."""
    _BUILDING.append(construction)
    try:
        yield
    finally:
        _BUILDING.pop()


def construction() -> Construction:
    """The current construction (an empty one outside the loader)."""
    return _BUILDING[-1] if _BUILDING else Construction()


class _Handling:
    """The context of `Engine.handling` (a class: it runs around every handler). While node
    code runs, `time.sleep` called from its thread is the contract breach that names the
    rclpy idiom; another thread's call goes to the sleep in place before."""

    __slots__ = ("engine", "ctx", "sleep", "thread")

    def __init__(self, engine: Engine, ctx: Context) -> None:
        self.engine, self.ctx = engine, ctx

    def __enter__(self) -> None:
        self.engine.ctx = self.ctx
        self.engine.synced = None  # node code may change the engine's records
        current.enter(self.engine)
        self.thread = threading.get_ident()
        self.sleep, _time.sleep = _time.sleep, self.blocked_sleep

    def __exit__(self, *_exc: object) -> None:
        _time.sleep = self.sleep
        current.leave()
        self.engine.ctx = None

    def blocked_sleep(self, seconds: float | SupportsIndex) -> None:
        """`time.sleep` while node code runs."""
        if threading.get_ident() != self.thread:
            self.sleep(seconds)
            return
        raise ContractError("time.sleep() blocks the executor inside an rclpy callback",
                            "use a timer (node.create_timer) and continue in its callback")


class Engine:
    """rclpy's executor semantics for one node (module docstring)."""

    def __init__(self, node: Any, name: str, namespace: str, adapter: Any) -> None:
        self.node = node
        self.name = name
        self.namespace = namespace
        self.adapter = adapter  # the contract node (ctx.after/ctx.call need its methods)
        self.ctx: Context | None = None
        self.groups: list[Any] = []
        self.publishers: list[PublisherEntry] = []
        self.subscriptions: list[SubscriptionEntry] = []
        self.services: list[ServiceEntry] = []
        self.clients: list[ClientEntry] = []
        self.dyn = Dynamic()
        self.synced: Any = None  # the records `dyn` holds, when known (twinfleet.rclpy.state)
        self.at_start: list[Callable[[Context], None]] = []  # effects of __init__
        self.clock_read = False
        self.declared: dict[str, Any] = {}  # parameter name -> (descriptor, type)
        self.overrides: dict[str, Any] = {}  # the launch's parameter values
        self.handles: dict[tuple[str, int], Any] = {("node", 0): node}
        self.tasks = Tasks(self)

    def handle(self, kind: str, index: int) -> Any:
        """The framework object a state refers to by kind and index."""
        if kind == "group":
            return self.groups[index]
        return self.handles[(kind, index)]

    # ------------------------------------------------------------------ groups

    def group_index(self, group: Any) -> int:
        """The index of a callback group (registered on first use)."""
        for i, known in enumerate(self.groups):
            if known is group:
                return i
        self.groups.append(group)
        return len(self.groups) - 1

    def busy(self, group: int | None) -> bool:
        """True while a suspended coroutine holds a mutually exclusive group."""
        if group is None or not self.groups[group].exclusive:
            return False
        return any(t.group == group for t in self.dyn.tasks)

    def group_of(self, kind: EntityKind, index: int) -> int:
        """The group of an entity."""
        if kind is EntityKind.TIMER:
            slot = self.dyn.timers[index]
            return 0 if slot is None else slot.group
        if kind is EntityKind.SUBSCRIPTION:
            return self.subscriptions[index].group
        if kind is EntityKind.SERVICE:
            return self.services[index].group
        return self.clients[index].group

    # ------------------------------------------------------------------ handlers

    def handling(self, ctx: Context) -> _Handling:
        """Run node code for one contract handler: effects go to `ctx`; sleeping is refused."""
        return _Handling(self, ctx)

    def start(self, ctx: Context) -> None:
        """The node starts: the effects of its `__init__`, then its timers' first firings."""
        with self.handling(ctx):
            for effect in self.at_start:
                effect(ctx)
            for index, slot in enumerate(self.dyn.timers):
                if slot is not None and not slot.canceled and slot.pending == 0:
                    self.schedule(index)

    def on_timer(self, ctx: Context, index: int) -> None:
        """A timer event: stale ones do nothing; the live one schedules the next and runs."""
        with self.handling(ctx):
            slot = self.dyn.timers[index]
            if slot is None:
                return
            slot.pending -= 1
            if slot.pending > 0 or slot.canceled:
                if slot.destroyed and slot.pending == 0:
                    self.dyn.timers[index] = None
                return
            self.schedule(index)
            self.dispatch(EntityKind.TIMER, index, ())

    def on_message(self, ctx: Context, index: int, msg: Any) -> None:
        """A sample for subscription `index`."""
        with self.handling(ctx):
            self.dispatch(EntityKind.SUBSCRIPTION, index, (msg,))

    def on_reply(self, ctx: Context, index: int, slot: int, reply: Any) -> None:
        """The reply to the call in slot `slot` of client `index`."""
        with self.handling(ctx):
            if isinstance(reply, CallError):
                return  # rclpy's future stays pending: a call without answer never completes
            self.dispatch(EntityKind.CLIENT, index, (reply, slot))

    def on_request(self, ctx: Context, index: int, request: Any) -> Any:
        """A request for service `index`: its response, frozen; None when the reply is
        deferred (its callback suspended, or it waits for its busy group), as rclpy's
        executor answers when the callback's task ends."""
        with self.handling(ctx):
            entry = self.services[index]
            if self.busy(entry.group):
                self.hold(Waiting(EntityKind.SERVICE, index, (request, ctx.defer_reply())))
                return None
            response = self.tasks.serve(entry, wire.thaw(request), None)
            self.drain()
            return None if response is DEFERRED else wire.freeze(response)

    # ------------------------------------------------------------------ dispatch

    def dispatch(self, kind: EntityKind, index: int, args: tuple[Any, ...]) -> None:
        """A callback became ready: run it now, or hold it while its group is busy."""
        if self.busy(self.group_of(kind, index)):
            self.hold(Waiting(kind, index, args))
        else:
            self.run(kind, index, args)
        self.drain()

    def hold(self, waiting: Waiting) -> None:
        """Queue a ready callback; a timer waits once, a subscription keeps its depth."""
        queue = self.dyn.waiting
        same = [w for w in queue if w.kind is waiting.kind and w.index == waiting.index]
        if waiting.kind is EntityKind.TIMER and same:
            return
        if waiting.kind is EntityKind.SUBSCRIPTION:
            depth = self.subscriptions[waiting.index].qos.depth
            if len(same) >= depth:
                queue.remove(same[0])
        queue.append(waiting)

    def drain(self) -> None:
        """Run waiting callbacks whose groups are free, one entity at a time, in any order."""
        while True:
            heads: list[Waiting] = []
            for w in self.dyn.waiting:
                if not self.busy(self.group_of(w.kind, w.index)) and not any(
                        h.kind is w.kind and h.index == w.index for h in heads):
                    heads.append(w)
            if not heads:
                return
            pick = heads[0] if len(heads) == 1 or self.ctx is None else self.ctx.choose(heads)
            self.dyn.waiting.remove(pick)
            self.run(pick.kind, pick.index, pick.args)

    def run(self, kind: EntityKind, index: int, args: tuple[Any, ...]) -> None:
        """Take one ready callback."""
        if kind is EntityKind.CLIENT:
            reply, slot = args
            calls = self.dyn.calls[index]
            future = calls[slot] if slot < len(calls) else None
            if future is not None:
                calls[slot] = None
                while calls and calls[-1] is None:  # one form per set of pending calls
                    calls.pop()
                future.set_result(wire.thaw(reply))
            return
        if kind is EntityKind.TIMER:
            slot = self.dyn.timers[index]
            if slot is not None and not slot.destroyed:
                self.tasks.start(slot.callback, (), slot.group)
            return
        if kind is EntityKind.SERVICE:
            request, token = args
            self.tasks.serve(self.services[index], wire.thaw(request), token)
            return
        entry = self.subscriptions[index]
        self.tasks.start(entry.callback, (wire.thaw(args[0]),), entry.group)

    def future_done(self, future: Any, callbacks: list[Callable[..., Any]]) -> None:
        """A future completed: its done callbacks run, then the coroutines awaiting it resume."""
        for callback in callbacks:
            self.tasks.start(callback, (future,), None)
        self.tasks.resume_awaiting(future)

    # ------------------------------------------------------------------ effects

    def now_ms(self) -> int:
        """The time the running callback sees (0 while the node is built)."""
        self.clock_read = True
        return 0 if self.ctx is None else self.ctx.now()

    def effect(self, apply: Callable[[Context], None]) -> None:
        """Carry out an effect now, or at start when the node is still being built."""
        if self.ctx is None:
            self.at_start.append(apply)
        else:
            apply(self.ctx)

    def publish(self, index: int, msg: Any) -> None:
        """Publish a copy of `msg` (rclpy's publish copies too)."""
        entry = self.publishers[index]
        if not isinstance(msg, entry.msg_type):
            raise TypeError(f"{self.name}: publisher of {entry.topic!r} takes "
                            f"{entry.msg_type.__name__}, got {type(msg).__name__}")
        frozen = wire.freeze(msg)
        self.effect(lambda ctx: ctx.publish(entry.topic, frozen))

    def call(self, index: int, request: Any, future: Any) -> None:
        """Send a request of client `index`; its reply completes `future`."""
        entry = self.clients[index]
        frozen = wire.freeze(request)
        future._engine = self
        calls = self.dyn.calls[index]
        slot = next((k for k, f in enumerate(calls) if f is None), len(calls))
        if slot >= CALL_SLOTS:
            raise ContractError(f"{self.name}: client {entry.name!r} has {CALL_SLOTS} calls "
                                "waiting for replies, as many as twinfleet's rclpy follows",
                                "wait for a reply (await it, or call again from its done "
                                "callback) before calling once more")
        if slot == len(calls):
            calls.append(future)
        else:
            calls[slot] = future
        method = getattr(self.adapter, reply_method(index, slot))
        self.effect(lambda ctx: ctx.call(entry.name, frozen, method, timeout_ms=CALL_TIMEOUT_MS))

    def log(self, severity: str, logger: str, text: str) -> None:
        """A log line with its severity, into the event log (one logged while the node is
        built goes there when it starts; the loader's first, probing build logs nothing)."""
        if self.ctx is not None or self.adapter is not None:
            self.effect(lambda ctx: ctx.log("rclpy.log", severity=severity, logger=logger,
                                            msg=text))

    # ------------------------------------------------------------------ timers

    def add_timer(self, period_ms: int, callback: Callable[..., Any], group: int,
                  autostart: bool) -> int:
        """A new timer; running at once when made by a callback (at start when built)."""
        slot = TimerSlot(period_ms, callback, group, canceled=not autostart)
        timers = self.dyn.timers
        index = next((i for i, t in enumerate(timers) if t is None), len(timers))
        if index == len(timers):
            timers.append(slot)
        else:
            timers[index] = slot
        if autostart and self.ctx is not None:
            self.schedule(index)
        return index

    def schedule(self, index: int) -> None:
        """The next firing of timer `index`, one period from now."""
        slot = self.dyn.timers[index]
        assert slot is not None and self.ctx is not None
        slot.pending += 1
        self.ctx.after(slot.period_ms, self.adapter.timer, index)

    def timer_slot(self, index: int) -> TimerSlot:
        """Timer `index` (which the caller holds a handle of)."""
        slot = self.dyn.timers[index]
        if slot is None or slot.destroyed:
            raise RuntimeError(f"{self.name}: the timer was destroyed")
        return slot

    def cancel_timer(self, index: int) -> None:
        """Stop a timer; its scheduled firing becomes stale."""
        self.timer_slot(index).canceled = True

    def reset_timer(self, index: int) -> None:
        """Restart a timer: its next firing is one period from now."""
        slot = self.timer_slot(index)
        slot.canceled = False
        if self.ctx is not None:
            self.schedule(index)

    def destroy_timer(self, index: int) -> None:
        """Remove a timer; its slot is reused once no firing of it is scheduled."""
        slot = self.timer_slot(index)
        slot.canceled = slot.destroyed = True
        if slot.pending == 0:
            self.dyn.timers[index] = None
