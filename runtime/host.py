"""NodeHost: runs one node on an asyncio loop over a `Transport`.

Theory of operation. Everything that makes a handler run — a sample, a
service request, a timer, an `after`, a call's reply, a liveliness change —
becomes an *inbox item* keyed by ``(arrival_ms, priority, seq)``: items that
arrive in the same fleet millisecond run in handler-priority order, others in
arrival order (timers arrive at their *due* time, so lateness of the loop does
not reorder them). One drain callback pops items and runs them one at a time
through `runtime.dispatch.run_handler`, then performs the recorded effects:

* ``Publish`` → `transport.put` of a msgpack envelope with a per-topic seq;
* ``Call``    → `transport.query`; the reply (or a `CallError` for "timeout",
  "no server", "server error: ...") becomes an inbox item for ``reply_to``;
  the timeout is a clock timer, so it scales with ``--time-scale``;
* ``After``   → a clock timer at ``now + delay`` that enqueues the handler;
* ``Fail``    → logged, counted, a `Violation` published on ``/violations``;
* ``Log``     → one ``t=<ms> <event> key=value ...`` line on ``out``.

Handler exceptions are logged (node, handler, message, traceback), counted and
published as violations; the node keeps serving unless ``stop_on_error``.
Undecodable samples are logged with their key, counted and dropped. Receivers
of reliable topics count sequence gaps per (sender, topic).
"""

from __future__ import annotations

import asyncio
import hashlib
import heapq
import itertools
import random
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, TextIO, final

from runtime.clock import Clock, TimerHandle
from runtime.context import Call, Context, Fail, Log, Publish
from runtime.dispatch import HandlerError, HandlerOutcome, run_handler
from runtime.messages import (
    CallError,
    DecodeError,
    NodeAlive,
    Violation,
    decode,
    encode,
)
from runtime.names import key_expr
from runtime.node import QOS_DEFAULT, HandlerSpec, Node, Reliability
from runtime.transport import Respond, Transport, graph_key, parse_graph_key

LIVELINESS_TOPIC = "/_liveliness"
VIOLATIONS_TOPIC = "/violations"
_DRAIN_BATCH = 256  # handlers per loop callback before yielding to I/O


def derive_seed(seed: int, node_name: str) -> int:
    """A per-node seed that is stable across processes and PYTHONHASHSEED values."""
    digest = hashlib.sha256(f"{seed}:{node_name}".encode()).digest()
    return int.from_bytes(digest[:8], "big")


@final
class RandomChooser:
    """Answers `ctx.choose` live from a seeded `random.Random`."""

    def __init__(self, seed: int) -> None:
        self._rng = random.Random(seed)

    def choose(self, n: int) -> int:
        """A uniformly random index in range(n)."""
        return self._rng.randrange(n)


@dataclass(frozen=True, slots=True)
class HostStatistics:
    """A snapshot of a host's counters."""

    received: int
    dropped_undecodable: int
    handler_errors: int
    failures: int
    gaps: int
    inbox_depth: int
    timers_pending: int
    published: int
    handled: int


@dataclass(order=True, slots=True)
class _Item:
    arrival_ms: int
    priority: int
    seq: int
    method: str = ""
    args: tuple[Any, ...] = ()
    respond: Respond | None = None


@final
class NodeHost:
    """Runs `node`'s handlers on the loop, one at a time, over `transport`.

    Args:
        node: the node object (its `state` is changed by its handlers).
        transport: an unopened or opened `Transport`; the caller opens and closes it.
        clock: fleet time and timer scheduling (`FleetClock` live, `ManualClock` in tests).
        seed: fleet seed; the node's chooser is seeded with `derive_seed(seed, node.name)`.
        fleet: fleet name, the second chunk of every key expression.
        stop_on_error: stop `run()` (and set `failed`) at the first handler exception.
        wait_for: node names whose liveliness tokens must be seen before `@on_start` runs.
        ready_timeout_s: give up waiting for `wait_for` after this many wall seconds.
        out: where log lines go.
    """

    def __init__(self, node: Node, transport: Transport, clock: Clock, *, seed: int,
                 fleet: str, stop_on_error: bool = False, wait_for: Sequence[str] = (),
                 ready_timeout_s: float = 10.0, out: TextIO | None = None) -> None:
        self.node, self.transport, self.clock = node, transport, clock
        self.fleet, self.stop_on_error = fleet, stop_on_error
        self.wait_for, self.ready_timeout_s = tuple(wait_for), ready_timeout_s
        self.out = out if out is not None else sys.stdout
        self.spec = node.spec()
        self.publications = {node.resolve(k): v for k, v in self.spec.publications.items()}
        self.failed = False
        self.alive: set[str] = set()
        self._chooser = RandomChooser(derive_seed(seed, node.name))
        self._inbox: list[_Item] = []
        self._counter = itertools.count()
        self._timers: dict[int, TimerHandle] = {}
        self._calls: dict[int, tuple[str, str, TimerHandle]] = {}
        self._pub_seq: dict[str, int] = {}
        self._last_seq: dict[tuple[str, str], int] = {}
        self._drain_scheduled = False
        self._stop_requested = False
        self._stop: asyncio.Event | None = None
        self._alive_changed: asyncio.Event | None = None
        self._n = dict.fromkeys(("received", "undecodable", "errors", "failures", "gaps",
                                 "published", "handled"), 0)

    # ---------------------------------------------------------------- lifecycle

    async def run(self) -> None:
        """Declare the node's graph, wait for peers, run `@on_start`, then serve until stopped."""
        self._stop = asyncio.Event()
        if self._stop_requested:
            return
        self._alive_changed = asyncio.Event()
        try:
            self._declare()
            await self._wait_ready()
            now = self.clock.now_ms()
            self._line(f"t={now} started ({len(self.alive)} nodes alive)")
            for spec in self.spec.of_kind("start"):
                self._enqueue(now, spec.priority, spec.method, ())
            for spec in self.spec.of_kind("every"):
                self._arm_every(spec, self._first_due(spec, now))
            await self._stop.wait()
        finally:
            self._cancel_timers()

    def stop(self) -> None:
        """Make `run()` return (safe to call from signal handlers on the loop)."""
        self._stop_requested = True
        if self._stop is not None:
            self._stop.set()
        if self._alive_changed is not None:
            self._alive_changed.set()

    def statistics(self) -> HostStatistics:
        """Counters since start, as a frozen record."""
        n = self._n
        return HostStatistics(received=n["received"], dropped_undecodable=n["undecodable"],
                              handler_errors=n["errors"], failures=n["failures"], gaps=n["gaps"],
                              inbox_depth=len(self._inbox), timers_pending=len(self._timers),
                              published=n["published"], handled=n["handled"])

    def idle(self) -> bool:
        """True when no inbox item is waiting and no drain is scheduled."""
        return not self._inbox and not self._drain_scheduled

    def _declare(self) -> None:
        node, t = self.node, self.transport
        for spec in self.spec.of_kind("subscribe"):
            topic = node.resolve(spec.name or "")
            if topic == LIVELINESS_TOPIC:
                continue
            t.subscribe(key_expr(self.fleet, topic), self._make_deliver(spec, topic), spec.qos)
            t.announce(graph_key(self.fleet, "sub", node.name, topic))
        for spec in self.spec.of_kind("service"):
            name = node.resolve(spec.name or "")
            t.serve(key_expr(self.fleet, name), self._make_serve(spec))
            t.announce(graph_key(self.fleet, "srv", node.name, name))
        t.watch(graph_key(self.fleet, "node", "*"), self._on_liveliness)
        t.announce(graph_key(self.fleet, "node", node.name))

    async def _wait_ready(self) -> None:
        assert self._alive_changed is not None
        wanted = set(self.wait_for)
        loop = asyncio.get_running_loop()
        deadline = loop.time() + self.ready_timeout_s
        while not wanted <= self.alive and not self._stop_requested:
            remaining = deadline - loop.time()
            if remaining <= 0:
                missing = ", ".join(sorted(wanted - self.alive))
                self._line(f"warning: starting without peers {missing} "
                           f"(not alive after {self.ready_timeout_s:g} s)", err=True)
                return
            self._alive_changed.clear()
            try:
                await asyncio.wait_for(self._alive_changed.wait(), remaining)
            except TimeoutError:
                continue

    # ---------------------------------------------------------------- arrivals

    def _make_deliver(self, spec: HandlerSpec, topic: str) -> Callable[[str, bytes], None]:
        count_gaps = spec.qos.reliability is Reliability.RELIABLE

        def deliver(key: str, payload: bytes) -> None:
            self._n["received"] += 1
            try:
                env = decode(payload)
            except DecodeError as exc:
                self._n["undecodable"] += 1
                self._line(f"dropped undecodable sample on {key}: {exc}", err=True)
                return
            if count_gaps:
                self._count_gap(env.sender, topic, env.seq)
            self._enqueue(self.clock.now_ms(), spec.priority, spec.method, (env.msg,))

        return deliver

    def _count_gap(self, sender: str, topic: str, seq: int) -> None:
        last = self._last_seq.get((sender, topic))
        if last is not None and seq > last + 1:
            self._n["gaps"] += seq - last - 1
        self._last_seq[(sender, topic)] = seq

    def _make_serve(self, spec: HandlerSpec) -> Callable[[bytes, Respond], None]:
        def on_request(payload: bytes, respond: Respond) -> None:
            self._n["received"] += 1
            try:
                request = decode(payload).msg
            except DecodeError as exc:
                self._n["undecodable"] += 1
                self._line(f"undecodable request for {spec.name}: {exc}", err=True)
                respond(None, f"server error: undecodable request ({exc})")
                return
            self._enqueue(self.clock.now_ms(), spec.priority, spec.method, (request,), respond)

        return on_request

    def _on_liveliness(self, key: str, alive: bool) -> None:
        name = parse_graph_key(key)[2]
        (self.alive.add if alive else self.alive.discard)(name)
        if self._alive_changed is not None:
            self._alive_changed.set()
        spec = next((s for s in self.spec.of_kind("subscribe")
                     if self.node.resolve(s.name or "") == LIVELINESS_TOPIC), None)
        if spec is not None:
            self._enqueue(self.clock.now_ms(), spec.priority, spec.method, (NodeAlive(name, alive),))

    def _enqueue(self, arrival_ms: int, priority: int, method: str, args: tuple[Any, ...],
                 respond: Respond | None = None) -> None:
        heapq.heappush(self._inbox, _Item(arrival_ms, priority, next(self._counter),
                                          method, args, respond))
        if not self._drain_scheduled:
            self._drain_scheduled = True
            asyncio.get_running_loop().call_soon(self._drain)

    def _drain(self) -> None:
        self._drain_scheduled = False
        for _ in range(_DRAIN_BATCH):
            if not self._inbox or (self._stop is not None and self._stop.is_set()):
                return
            self._dispatch(heapq.heappop(self._inbox))
        if self._inbox and not self._drain_scheduled:
            self._drain_scheduled = True
            asyncio.get_running_loop().call_soon(self._drain)

    # ---------------------------------------------------------------- dispatch

    def _dispatch(self, item: _Item) -> None:
        now = self.clock.now_ms()
        ctx = Context(self.node, now_ms=now, chooser=self._chooser)
        outcome = run_handler(self.node, item.method, ctx, item.args,
                              expects_reply=item.respond is not None)
        self._n["handled"] += 1
        if outcome.error is not None:
            self._handler_error(outcome.error, item)
        self._perform(outcome, now)
        if item.respond is not None:
            if outcome.error is None:
                item.respond(encode(outcome.reply, stamp_ms=now, sender=self.node.name), "")
            else:
                item.respond(None, f"server error: {outcome.error.message}")

    def _handler_error(self, error: HandlerError, item: _Item) -> None:
        self._n["errors"] += 1
        detail = ", ".join(repr(a)[:120] for a in item.args)
        self._line(f"error in handler {error} (args: {detail})", err=True)
        if error.traceback:
            self._line(error.traceback.rstrip(), err=True)
        self._publish(VIOLATIONS_TOPIC, Violation(error.node, error.handler, error.message),
                      self.clock.now_ms())
        if self.stop_on_error:
            self.failed = True
            self._line("stopping: live.stop_on_error is set", err=True)
            self.stop()

    def _perform(self, outcome: HandlerOutcome, now: int) -> None:
        for effect in outcome.effects:
            match effect:
                case Publish(topic, msg):
                    self._publish(topic, msg, now)
                case Call():
                    self._call(effect, now)
                case Fail(reason):
                    self._n["failures"] += 1
                    self._line(f"t={now} FAIL {reason}", err=True)
                    self._publish(VIOLATIONS_TOPIC, Violation(self.node.name, "", reason), now)
                case Log(event, fields):
                    text = " ".join(f"{k}={v!r}" for k, v in fields)
                    self._line(f"t={now} {event}" + (f" {text}" if text else ""))
                case _:  # After
                    due = now + effect.delay_ms
                    spec = self.spec.by_method(effect.handler)
                    self._timer(due, spec.priority if spec else 0, effect.handler, effect.args)

    def _publish(self, topic: str, msg: Any, now: int) -> None:
        seq = self._pub_seq.get(topic, 0) + 1
        self._pub_seq[topic] = seq
        if seq == 1:
            self.transport.announce(graph_key(self.fleet, "pub", self.node.name, topic))
        qos = self.publications.get(topic, QOS_DEFAULT)
        payload = encode(msg, stamp_ms=now, seq=seq, sender=self.node.name)
        self.transport.put(key_expr(self.fleet, topic), payload, qos)
        self._n["published"] += 1

    # ---------------------------------------------------------------- timers and calls

    def _timer(self, due_ms: int, priority: int, method: str, args: tuple[Any, ...]) -> None:
        tid = next(self._counter)
        self._timers[tid] = self.clock.call_at(due_ms, self._fire, tid, due_ms, priority,
                                               method, args)

    def _fire(self, tid: int, due_ms: int, priority: int, method: str,
              args: tuple[Any, ...]) -> None:
        self._timers.pop(tid, None)
        self._enqueue(due_ms, priority, method, args)

    def _first_due(self, spec: HandlerSpec, now: int) -> int:
        period = self.node.period_ms(spec)
        k = max(1, (now - spec.phase_ms) // period + 1)
        return spec.phase_ms + k * period

    def _arm_every(self, spec: HandlerSpec, due_ms: int) -> None:
        tid = next(self._counter)
        self._timers[tid] = self.clock.call_at(due_ms, self._fire_every, tid, spec, due_ms)

    def _fire_every(self, tid: int, spec: HandlerSpec, due_ms: int) -> None:
        self._timers.pop(tid, None)
        self._enqueue(due_ms, spec.priority, spec.method, ())
        period = self.node.period_ms(spec)
        next_due = due_ms + period
        now = self.clock.now_ms()
        if next_due + period <= now:  # far behind (suspended process): skip missed periods
            next_due = self._first_due(spec, now)
        self._arm_every(spec, next_due)

    def _call(self, call: Call, now: int) -> None:
        cid = next(self._counter)
        timer = self.clock.call_at(now + call.timeout_ms, self._call_done, cid, None, "timeout")
        self._calls[cid] = (call.service, call.reply_to, timer)
        payload = encode(call.request, stamp_ms=now, sender=self.node.name)
        wall_ms = self.clock.real_seconds(call.timeout_ms) * 1000.0 + 500.0
        self.transport.query(key_expr(self.fleet, call.service), payload, wall_ms,
                             lambda reply, reason: self._call_done(cid, reply, reason))

    def _call_done(self, cid: int, reply: bytes | None, reason: str) -> None:
        pending = self._calls.pop(cid, None)
        if pending is None:
            return  # already answered or timed out
        service, reply_to, timer = pending
        timer.cancel()
        result: Any = CallError(service, reason or "no reply")
        if reply is not None:
            try:
                result = decode(reply).msg
            except DecodeError as exc:
                result = CallError(service, f"server error: undecodable reply ({exc})")
        spec = self.spec.by_method(reply_to)
        self._enqueue(self.clock.now_ms(), spec.priority if spec else 0, reply_to, (result,))

    def _cancel_timers(self) -> None:
        for handle in self._timers.values():
            handle.cancel()
        self._timers.clear()
        for _, _, handle in self._calls.values():
            handle.cancel()
        self._calls.clear()

    def _line(self, text: str, *, err: bool = False) -> None:
        stream = sys.stderr if err and self.out is sys.stdout else self.out
        print(text, file=stream, flush=True)
