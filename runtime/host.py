"""NodeHost: runs one node on an asyncio loop over a `Transport`.

Theory of operation. Everything that makes a handler run — a sample, a
service request, a timer, an `after`, a call's reply, a liveliness change —
becomes an *inbox item* keyed by ``(arrival_ms, priority, seq)``: items that
arrive in the same fleet millisecond run in handler-priority order, others in
arrival order (timers arrive at their *due* time, so lateness of the loop does
not reorder them). One drain callback pops items and runs them one at a time
through `runtime.dispatch.run_handler`, then performs the recorded effects:

* ``Publish`` → a put (through `transport.publisher`, fetched once per topic) of a
  msgpack envelope with a per-topic seq;
* ``Call``    → `transport.query`; the reply (or a `CallError` for "timeout",
  "no server", "server error: ...") becomes an inbox item for ``reply_to``;
  the timeout is a clock timer, so it scales with ``--time-scale``;
* ``After``   → a clock timer at ``now + delay`` that enqueues the handler;
* ``Fail``    → logged, counted, a `Violation` published on ``/violations``;
* ``Log``     → one ``t=<ms> <event> key=value ...`` line on ``out``.

Handler exceptions are logged (node, handler, message, traceback), counted and
published as violations; the node keeps serving unless ``stop_on_error``.
Undecodable samples are logged with their key, counted and dropped. Receivers
count sequence gaps per (sender, topic): on reliable topics as ``gaps`` (a
loss the tests treat as a bug), on best-effort ones as ``dropped_best_effort``.
Sequence numbers come from the sender, so a jump by more than ``MAX_GAP`` is
not believed to be a loss (a forged or corrupt number would otherwise add
billions of gaps): it is counted once as ``sequence_jumps``.

Bounded inbox. Each subscription keeps at most ``qos.depth`` received but not
yet handled messages (KEEP_LAST, a ``deque(maxlen=depth)``): when a message
arrives with ``depth`` already waiting, the oldest waiting one is dropped and
counted (``dropped_keep_last``); the inbox holds one slot per waiting message,
and a slot runs the oldest message of its subscription. Gaps are counted
before that, on every decoded sample, so they measure losses below the host
(network, or the transport's own bounded hand-off, ``dropped_overflow``).

Hot path. Each subscription's delivery closure binds its queue, counters and
per-topic last-seq map once; a sample costs one `decode_fields` (no Envelope
object), a gap check, a deque append and a heap push. Inbox entries are plain
tuples (compared in C). With a transport that calls back after each burst of
samples (`after_burst`), deliveries schedule no extra loop callback: the burst's
handlers run in the same loop iteration. Each topic's put function and sequence
counter are fetched once, and a handler's effects are performed right after it
returns, in the order it recorded them.

Event log and replay gate (issue 6): with ``events=EventLog(...)`` every
dispatched event becomes one flushed JSON line, and with ``gated=True`` a
replay coordinator grants each event in a trace's order
(`runtime.replay_gate`). Without either, the hot path only pays a few
`None` tests.

Start first. Whatever arrives while a node waits for its peers stays in the
inbox until its `@on_start` handlers have run, as in the checker, whose
initial world runs every start handler before any event.
"""

from __future__ import annotations

import asyncio
import hashlib
import heapq
import itertools
import random
import sys
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, TextIO, final

from twinfleet.runtime.clock import Clock, TimerHandle
from twinfleet.runtime.context import Call, Context, Effect, Fail, Log, Publish
from twinfleet.runtime.dispatch import HandlerError, invoke
from twinfleet.runtime.messages import (
    CallError,
    DecodeError,
    Envelope,
    NodeAlive,
    Violation,
    decode,
    decode_fields,
    encode,
)
from twinfleet.runtime.names import key_expr
from twinfleet.runtime.node import QOS_DEFAULT, HandlerSpec, Node, Reliability
from twinfleet.runtime.replay_gate import (
    EventLog,
    EventMeta,
    LogicalClock,
    ReadyEvent,
    RecordingChooser,
    ReplayGate,
    gate_key,
    payload_digest,
    state_digest,
    summarise,
)
from twinfleet.runtime.snapshot import snapshot
from twinfleet.runtime.transport import Respond, Transport, graph_key, parse_graph_key

LIVELINESS_TOPIC = "/_liveliness"
VIOLATIONS_TOPIC = "/violations"
MAX_GAP = 1 << 16  # a larger leap in one sender's sequence numbers is not counted as lost messages
_DRAIN_BATCH = 256  # handlers per loop callback before yielding to I/O
_BEFORE_ALL = -(1 << 62)  # inbox arrival key of start handlers


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
    dropped_keep_last: int = 0
    dropped_overflow: int = 0
    dropped_best_effort: int = 0
    sequence_jumps: int = 0  # sequence numbers that leapt by more than MAX_GAP (not counted as gaps)


@final
class _Subscription:
    """One declared subscription: its handler and its KEEP_LAST queue of waiting messages."""

    __slots__ = ("method", "priority", "topic", "gap_counter", "waiting", "traced")

    def __init__(self, spec: HandlerSpec, topic: str, traced: bool = False) -> None:
        self.method, self.priority, self.topic = spec.method, spec.priority, topic
        self.traced = traced  # `waiting` holds envelopes (the sender is logged), not messages
        reliable = spec.qos.reliability is Reliability.RELIABLE
        self.gap_counter = "gaps" if reliable else "best_effort"  # a bug vs. drops by design
        self.waiting: deque[Any] = deque(maxlen=max(1, spec.qos.depth))


# An inbox entry: (arrival_ms, priority, seq, work) with work either a _Subscription
# (run its oldest waiting message) or (method, args, respond, meta). seq is unique, so
# tuples never compare their work.
_Entry = tuple[int, int, int, Any]


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
        events: log every dispatched event there (module docstring).
        gated: run only events granted by a replay coordinator (needs a `LogicalClock`).
    """

    def __init__(self, node: Node, transport: Transport, clock: Clock, *, seed: int,
                 fleet: str, stop_on_error: bool = False, wait_for: Sequence[str] = (),
                 ready_timeout_s: float = 10.0, out: TextIO | None = None,
                 events: EventLog | None = None, gated: bool = False) -> None:
        if gated and not isinstance(clock, LogicalClock):
            raise ValueError("a gated NodeHost needs a LogicalClock")
        self.node, self.transport, self.clock = node, transport, clock
        self.fleet, self.stop_on_error = fleet, stop_on_error
        self.wait_for, self.ready_timeout_s = tuple(wait_for), ready_timeout_s
        self.out = out if out is not None else sys.stdout
        self.spec = node.spec()
        self.publications = {node.resolve(k): v for k, v in self.spec.publications.items()}
        self.failed = False
        self.alive: set[str] = set()
        self._chooser = RandomChooser(derive_seed(seed, node.name))
        self._inbox: list[_Entry] = []
        self._counter = itertools.count()
        self._timers: dict[int, TimerHandle] = {}
        self._calls: dict[int, tuple[str, str, TimerHandle]] = {}
        self._topics: dict[str, list[Any]] = {}  # topic -> [put(payload), last seq]
        self._last_seq: dict[str, dict[str, int]] = {}  # topic -> sender -> last seq
        self._priorities = {s.method: s.priority for s in self.spec.handlers}
        self._liveliness = next((s for s in self.spec.of_kind("subscribe")
                                 if node.resolve(s.name or "") == LIVELINESS_TOPIC), None)
        # Nothing runs before @on_start, as in the checker (start handlers are constructors):
        # what arrives while the node waits for its peers stays in the inbox until run()
        # has queued the start handlers first and starts draining.
        self._drain_scheduled = True
        self._flushes_bursts = False  # the transport calls `_flush` after each burst
        self._started = False
        self._stop_requested = False
        self._stop: asyncio.Event | None = None
        self._alive_changed: asyncio.Event | None = None
        self._n = dict.fromkeys(("received", "undecodable", "errors", "failures", "gaps",
                                 "published", "handled", "keep_last", "best_effort",
                                 "seq_jumps"), 0)
        self._events = events
        self._gate = ReplayGate(self) if gated else None
        self._traced = events is not None or gated  # keep each event's kind and sender

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
            name = self.node.name
            for spec in self.spec.of_kind("start"):  # ahead of anything that already arrived
                self._enqueue(_BEFORE_ALL, spec.priority, spec.method, (), None,
                              ("start", name, "", 0, None, now) if self._traced else None)
            self._started = True
            asyncio.get_running_loop().call_soon(self._drain)
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
        transport_stats = getattr(self.transport, "statistics", None)
        overflow = transport_stats().get("overflow", 0) if callable(transport_stats) else 0
        return HostStatistics(received=n["received"], dropped_undecodable=n["undecodable"],
                              handler_errors=n["errors"], failures=n["failures"], gaps=n["gaps"],
                              inbox_depth=len(self._inbox) + (len(self._gate.ready)
                                                              if self._gate else 0),
                              timers_pending=len(self._timers),
                              published=n["published"], handled=n["handled"],
                              dropped_keep_last=n["keep_last"], dropped_overflow=overflow,
                              dropped_best_effort=n["best_effort"],
                              sequence_jumps=n["seq_jumps"])

    def idle(self) -> bool:
        """True when nothing can run now: no inbox item waits and no drain is scheduled,
        or the node has not started yet (what arrives waits for its `@on_start`)."""
        return not self._started or (not self._inbox and not self._drain_scheduled)

    def _declare(self) -> None:
        node, t = self.node, self.transport
        after_burst = getattr(t, "after_burst", None)
        if after_burst is not None:  # run what a burst of samples brought before the next poll
            after_burst(self._flush)
            self._flushes_bursts = True
        if self._gate is not None:  # before the node token: the coordinator waits for that
            t.serve(gate_key(self.fleet, node.name), self._gate.on_request)
        for spec in self.spec.of_kind("subscribe"):
            topic = node.resolve(spec.name or "")
            if topic == LIVELINESS_TOPIC:
                continue
            t.subscribe(key_expr(self.fleet, topic), self._make_deliver(spec, topic), spec.qos)
            t.announce(graph_key(self.fleet, "sub", node.name, topic))
        for spec in self.spec.of_kind("service"):
            name = node.resolve(spec.name or "")
            t.serve(key_expr(self.fleet, name), self._make_serve(spec, name))
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
        if self._gate is not None:
            return self._make_gated_deliver(spec, topic, self._gate)
        traced = self._events is not None
        sub = _Subscription(spec, topic, traced)
        # Everything the closure needs is bound once here: one sample costs a decode, a
        # gap check, a deque append and a heap push, with no attribute chains.
        n, now_ms, counter, push = self._n, self.clock.now_ms, self._counter, heapq.heappush
        inbox, waiting, priority, gap_counter = self._inbox, sub.waiting, sub.priority, sub.gap_counter
        last_seq = self._last_seq.setdefault(topic, {})  # shared by subscriptions of one topic
        wake, undecodable = self._wake, self._undecodable

        def deliver(key: str, payload: bytes) -> None:
            n["received"] += 1
            try:
                msg, stamp, seq, sender = decode_fields(payload)
            except Exception as exc:  # DecodeError (anything else would be a codec bug)
                undecodable(key, exc)
                return
            last = last_seq.get(sender)
            if last is not None and seq > last + 1:
                if seq - last <= MAX_GAP:
                    n[gap_counter] += seq - last - 1
                else:  # not a loss: a sender that lies about its numbers, or a corrupt one
                    n["seq_jumps"] += 1
            last_seq[sender] = seq
            if len(waiting) == waiting.maxlen:  # KEEP_LAST: the oldest waiting message goes
                waiting.append(Envelope(msg, stamp, seq, sender) if traced else msg)
                n["keep_last"] += 1
                return
            waiting.append(Envelope(msg, stamp, seq, sender) if traced else msg)
            push(inbox, (now_ms(), priority, next(counter), sub))
            if not self._drain_scheduled:
                wake()

        return deliver

    def _undecodable(self, key: str, exc: Exception) -> None:
        self._n["undecodable"] += 1
        self._line(f"dropped undecodable sample on {key}: {exc}", err=True)

    def _wake(self) -> None:
        """Make sure the inbox is drained: by the transport's end-of-burst flush if it has one."""
        self._drain_scheduled = True
        if not self._flushes_bursts:
            asyncio.get_running_loop().call_soon(self._drain)

    def _make_gated_deliver(self, spec: HandlerSpec, topic: str,
                            gate: ReplayGate) -> Callable[[str, bytes], None]:
        def deliver(key: str, payload: bytes) -> None:  # every message waits for its grant
            self._n["received"] += 1
            try:
                env = decode(payload)
            except Exception as exc:  # DecodeError
                self._undecodable(key, exc)
                return
            gate.add(ReadyEvent(spec.method, (env.msg,), None,
                            ("delivery", env.sender, topic, env.seq, env.stamp_ms, None)))

        return deliver

    def _make_serve(self, spec: HandlerSpec, name: str = "") -> Callable[[bytes, Respond], None]:
        def on_request(payload: bytes, respond: Respond) -> None:
            self._n["received"] += 1
            try:
                env = decode(payload)
            except Exception as exc:  # DecodeError (anything else would be a codec bug)
                self._n["undecodable"] += 1
                self._line(f"undecodable request for {spec.name}: {exc}", err=True)
                respond(None, f"server error: undecodable request ({exc})")
                return
            meta = (("request", env.sender, name, env.seq, env.stamp_ms, None)
                    if self._traced else None)
            self._enqueue(self.clock.now_ms(), spec.priority, spec.method, (env.msg,), respond,
                          meta)

        return on_request

    def _on_liveliness(self, key: str, alive: bool) -> None:
        name = parse_graph_key(key)[2]
        (self.alive.add if alive else self.alive.discard)(name)
        if self._alive_changed is not None:
            self._alive_changed.set()
        spec = self._liveliness
        if spec is not None:
            meta = ("liveliness", "", LIVELINESS_TOPIC, 0, None, None) if self._traced else None
            self._enqueue(self.clock.now_ms(), spec.priority, spec.method,
                          (NodeAlive(name, alive),), None, meta)

    def _enqueue(self, arrival_ms: int, priority: int, method: str, args: tuple[Any, ...],
                 respond: Respond | None = None, meta: EventMeta | None = None,
                 due_ms: int | None = None) -> None:
        if self._gate is not None:
            assert meta is not None
            self._gate.add(ReadyEvent(method, args, respond, meta))
            return
        heapq.heappush(self._inbox, (arrival_ms, priority, next(self._counter),
                                     (method, args, respond, meta, due_ms)))
        if not self._drain_scheduled:
            self._drain_scheduled = True
            asyncio.get_running_loop().call_soon(self._drain)

    def _flush(self) -> None:
        if self._inbox and self._drain_scheduled and self._started:
            self._drain()  # the call_soon'd drain then finds less (or nothing) to do

    def _drain(self) -> None:
        self._drain_scheduled = False
        inbox, pop = self._inbox, heapq.heappop
        for _ in range(_DRAIN_BATCH):
            if not inbox or self._stop_requested:
                return
            work = pop(inbox)[3]
            if type(work) is _Subscription:
                item = work.waiting.popleft()
                if work.traced:
                    self._dispatch(work.method, (item.msg,), None,
                                   ("delivery", item.sender, work.topic, item.seq, item.stamp_ms,
                                    None))
                else:
                    self._dispatch(work.method, (item,), None)
            else:
                method, args, respond, meta, due_ms = work
                self._dispatch(method, args, respond, meta, due_ms=due_ms)
        if inbox and not self._drain_scheduled:
            self._drain_scheduled = True
            asyncio.get_running_loop().call_soon(self._drain)

    # ---------------------------------------------------------------- dispatch

    def _dispatch(self, method: str, args: tuple[Any, ...], respond: Respond | None,
                  meta: EventMeta | None = None, chooser: RecordingChooser | None = None,
                  due_ms: int | None = None) -> tuple[list[Effect], HandlerError | None]:
        """Run one handler and perform its effects; return them and the error, if any."""
        # A timer runs at its due time, as in the checker: a late loop must not push every
        # later `ctx.after` of the chain later still (that drift adds up over a run).
        now = self.clock.now_ms() if due_ms is None else due_ms
        events = self._events
        if chooser is None and events is not None:
            chooser = RecordingChooser(self._chooser)
        ctx = Context(self.node, now, chooser or self._chooser)
        reply, error = invoke(self.node, method, ctx, args, respond is not None)
        self._n["handled"] += 1
        effects = ctx.effects
        if effects:
            try:
                self._perform(effects, now)
            except Exception as exc:  # e.g. a message msgpack cannot encode (an int ≥ 2**64)
                error = error or HandlerError(self.node.name, method, f"effect failed: {exc!r}")
        if respond is not None and error is None:
            try:
                reply = encode(reply, stamp_ms=now, sender=self.node.name)
            except Exception as exc:
                error = HandlerError(self.node.name, method, f"unencodable reply: {exc!r}")
        if events is not None:
            assert chooser is not None
            self._record(events, now, method, args, meta, chooser, error)
        if error is not None:
            self._handler_error(error, args)
        if respond is not None:
            if error is None:
                respond(reply, "")
            else:
                respond(None, f"server error: {error.message}")
        return effects, error

    def _record(self, events: EventLog, now: int, method: str, args: tuple[Any, ...],
                meta: EventMeta | None, chooser: RecordingChooser, error: HandlerError | None) -> None:
        kind, sender, topic, seq, stamp, due = meta or ("?", "", "", 0, None, None)
        try:
            digest = state_digest(snapshot(self.node.state))
        except Exception as exc:  # the checker reports this too; the log says it
            digest = f"unsnapshotable: {exc}"
        record = {"node": self.node.name, "t": now, "kind": kind, "handler": method,
                  "sender": sender, "topic": topic, "seq": seq, "stamp": stamp, "due": due,
                  "args": payload_digest(args), "summary": summarise(args),
                  "choices": chooser.indices, "options": chooser.options, "digest": digest}
        if error is not None:
            record["error"] = error.message
        events.event(record)

    def _handler_error(self, error: HandlerError, args: tuple[Any, ...]) -> None:
        self._n["errors"] += 1
        detail = ", ".join(repr(a)[:120] for a in args)
        self._line(f"error in handler {error} (args: {detail})", err=True)
        if error.traceback:
            self._line(error.traceback.rstrip(), err=True)
        self._publish(VIOLATIONS_TOPIC, Violation(error.node, error.handler, error.message),
                      self.clock.now_ms())
        if self.stop_on_error:
            self.failed = True
            self._line("stopping: live.stop_on_error is set", err=True)
            self.stop()

    def _perform(self, effects: list[Effect], now: int) -> None:
        for effect in effects:
            if type(effect) is Publish:  # by far the most frequent: no pattern matching
                self._publish(effect.topic, effect.msg, now)
                continue
            match effect:
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
                    self._timer(now + effect.delay_ms, self._priorities.get(effect.handler, 0),
                                effect.handler, effect.args)

    def _publish(self, topic: str, msg: Any, now: int) -> None:
        entry = self._topics.get(topic)
        if entry is None:
            qos = self.publications.get(topic, QOS_DEFAULT)
            entry = [self.transport.publisher(key_expr(self.fleet, topic), qos), 0]
            self._topics[topic] = entry
            self.transport.announce(graph_key(self.fleet, "pub", self.node.name, topic))
        seq = entry[1] + 1
        payload = encode(msg, stamp_ms=now, seq=seq, sender=self.node.name)  # may raise: no gap
        entry[1] = seq
        entry[0](payload)
        self._n["published"] += 1

    # ---------------------------------------------------------------- timers and calls

    def _timer(self, due_ms: int, priority: int, method: str, args: tuple[Any, ...]) -> None:
        if self._gate is not None:
            self._gate.add(ReadyEvent(method, args, None,
                                  ("after", self.node.name, "", 0, None, due_ms)))
            return
        tid = next(self._counter)
        self._timers[tid] = self.clock.call_at(due_ms, self._fire, tid, due_ms, priority,
                                               method, args)

    def _fire(self, tid: int, due_ms: int, priority: int, method: str,
              args: tuple[Any, ...]) -> None:
        self._timers.pop(tid, None)
        meta = ("after", self.node.name, "", 0, None, due_ms) if self._traced else None
        self._enqueue(due_ms, priority, method, args, None, meta, due_ms)

    def _first_due(self, spec: HandlerSpec, now: int) -> int:
        period = self.node.period_ms(spec)
        k = max(1, (now - spec.phase_ms) // period + 1)
        return spec.phase_ms + k * period

    def _arm_every(self, spec: HandlerSpec, due_ms: int) -> None:
        if self._gate is not None:  # re-armed by the gate once this firing has run
            self._gate.add(ReadyEvent(spec.method, (), None,
                                  ("timer", self.node.name, "", 0, None, due_ms)))
            return
        tid = next(self._counter)
        self._timers[tid] = self.clock.call_at(due_ms, self._fire_every, tid, spec, due_ms)

    def _fire_every(self, tid: int, spec: HandlerSpec, due_ms: int) -> None:
        self._timers.pop(tid, None)
        meta = ("timer", self.node.name, "", 0, None, due_ms) if self._traced else None
        self._enqueue(due_ms, spec.priority, spec.method, (), None, meta, due_ms)
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
        sender, seq, stamp = self.node.name, 0, None  # a CallError comes from the caller's side
        if reply is not None:
            try:
                env = decode(reply)
                result, sender, seq, stamp = env.msg, env.sender, env.seq, env.stamp_ms
            except DecodeError as exc:
                result = CallError(service, f"server error: undecodable reply ({exc})")
        meta = ("reply", sender, service, seq, stamp, None) if self._traced else None
        self._enqueue(self.clock.now_ms(), self._priorities.get(reply_to, 0), reply_to, (result,),
                      None, meta)

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
