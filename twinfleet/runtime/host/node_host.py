"""NodeHost: the thin asyncio loop that runs one node's `NodeCore` over a `Transport`.

The node's logic — ordering by (arrival, priority), KEEP_LAST, gap counting,
timers, calls, failures — is the sans-IO core's (`runtime.core.node_core`). The host
only connects it to the world:

* it declares the node's graph on the transport (subscriptions, services,
  liveliness tokens) and hands the core every arrival with its fleet time:
  samples, requests, replies (or why there is none), liveliness changes;
* it runs the core's ready handlers on the loop, one at a time, and performs
  their outputs in order: a `PublishOutput` on the topic's publisher (fetched once per
  topic), a `CallOutput` over the transport (its answer goes back to the core),
  a `ReplyOutput` to a request, a `LogOutput` on ``out``, a `StopOutput`;
* it sleeps until the core's next due time (`ctx.after`, `@every`, call
  timeouts) with one clock timer, re-armed when that time changes, so timers
  scale with ``--time-scale`` and a `ManualClock` drives them in tests.

Thread hand-off (docs/design.md §2). Transports call back on the loop; Zenoh's
threads only append to the transport's hand-off deque. With a transport that
calls back after each burst of samples (`after_burst`), deliveries schedule no
loop callback: the burst's handlers run in the same loop iteration. Other
arrivals and due timers schedule one drain with `call_soon`; a drain runs at
most ``_DRAIN_BATCH`` handlers before yielding to I/O.

Start first. Whatever arrives while a node waits for its peers stays in the
core until its `@on_start` handlers have run, as in the checker, whose initial
world runs every start handler before any event. With ``fleet_epoch`` the host
also waits for the launcher's epoch token and takes it as the clock's time 0:
what arrived before keeps its order (`NodeCore.shift_arrivals`) and the start
handlers run at time 0 (a ``restarted`` node's at the time it restarted).

Event log and replay gate: ``events=EventLog(...)`` makes the log an
observer of the core; ``gated=True`` puts a `ReplayGate` in charge (it needs a
`LogicalClock`): the core holds every message, nothing drains by itself, and
whatever arrives makes the gate look for the event its waiting grant names.
"""

from __future__ import annotations

import asyncio
import functools
import sys
from collections.abc import Callable, Sequence
from typing import TextIO, final

from twinfleet.runtime.contract.messages import CallFailure, DecodeError
from twinfleet.runtime.contract.node import QOS_DEFAULT, Node
from twinfleet.runtime.core.eventlog import EventLog
from twinfleet.runtime.core.guard import Rejected
from twinfleet.runtime.core.node_core import NodeCore
from twinfleet.runtime.core.outbox import (
    CallOutput,
    LogOutput,
    Output,
    PublishOutput,
    ReplyOutput,
    StopOutput,
)
from twinfleet.runtime.core.statistics import NodeStatistics
from twinfleet.runtime.host.clock import Clock, TimerHandle
from twinfleet.runtime.host.keys import KeyKind, kind_expr, node_key, parse_node_key, topic_key
from twinfleet.runtime.host.readiness import Readiness
from twinfleet.runtime.host.replay_gate import LogicalClock, ReplayGate
from twinfleet.runtime.host.transport import Respond, Transport

_DRAIN_BATCH = 256  # handlers per loop callback before yielding to I/O
_DROP_LINES = 20  # log lines about dropped samples before they are only counted


@final
class NodeHost:
    """Runs `node`'s handlers on the loop, one at a time, over `transport`.

    Args:
        node: the node object (its `state` is changed by its handlers).
        transport: an unopened or opened `Transport`; the caller opens and closes it.
        clock: fleet time and timer scheduling (`FleetClock` live, `ManualClock` in tests).
        seed: fleet seed; the node's chooser is seeded with `derive_seed(seed, node.name)`.
        fleet: fleet name, the second chunk of every key expression.
        stop_on_error: stop `run()` (and set `failed`) at the first handler failure.
        wait_for: node names whose liveliness tokens must be seen before `@on_start` runs.
        ready_timeout_s: give up waiting for `wait_for` after this many wall seconds.
        out: where log lines go.
        events: log every handler run there (an observer of the core).
        gated: run only events granted by a replay coordinator (needs a `LogicalClock`).
        stall_ms: the floor of the stall threshold (`NodeCore`: timers released later than
            max(stall_ms, twice the shortest timer period) count as stalls; None: never).
        fleet_epoch: also wait for the launcher's epoch token (`keys.epoch_key`) and
            take it as fleet time 0: `@on_start` then runs at time 0, as in the checker
            (a `restarted` node runs it at the time it restarted).
        restarted: this process replaces one of the node that died (a respawn).
    """

    def __init__(self, node: Node, transport: Transport, clock: Clock, *, seed: int,
                 fleet: str, stop_on_error: bool = False, wait_for: Sequence[str] = (),
                 ready_timeout_s: float = 10.0, out: TextIO | None = None,
                 events: EventLog | None = None, gated: bool = False,
                 stall_ms: int | None = None, fleet_epoch: bool = False,
                 restarted: bool = False) -> None:
        self.node, self.transport, self.clock, self.fleet = node, transport, clock, fleet
        self.fleet_epoch, self.restarted = fleet_epoch, restarted
        self.readiness = Readiness(wait_for, ready_timeout_s, fleet_epoch)
        self.out = out if out is not None else sys.stdout
        self.core = NodeCore(node, seed=seed, stop_on_error=stop_on_error, keep_last=not gated,
                             stall_ms=stall_ms)
        self.publications = {node.resolve(k): v for k, v in node.spec().publications.items()}
        self.failed = False
        self._dropped = 0
        if events is not None:
            self.core.observe(events)
        self._gate: ReplayGate | None = None
        if gated:
            if not isinstance(clock, LogicalClock):
                raise ValueError("a gated NodeHost needs a LogicalClock")
            self._gate = ReplayGate(self.core, clock, self.perform)
        # What to do when something became ready: drain it (live), or let the gate look.
        self._wake_burst: Callable[[], None] = self._schedule_burst
        self._wake_soon: Callable[[], None] = self._schedule_drain
        if self._gate is not None:
            self._wake_burst = self._wake_soon = self._gate.poll
        self._puts: dict[str, Callable[[bytes], None]] = {}
        # Nothing runs before @on_start (start handlers are constructors, as in the checker):
        # a drain counts as scheduled until run() has queued the start handlers.
        self._scheduled = True
        self._flushes_bursts = False  # the transport calls `_flush` after each burst
        self._started = False
        self._stop_requested = False
        self._stop: asyncio.Event | None = None
        self._wake_at: int | None = None
        self._wake_timer: TimerHandle | None = None

    # ---------------------------------------------------------------- lifecycle

    async def run(self) -> None:
        """Declare the node's graph, wait for peers, run `@on_start`, then serve until stopped."""
        self._stop = asyncio.Event()
        if self._stop_requested:
            return
        try:
            self._declare()
            missing = await self.readiness.wait()
            if missing is not None:
                self._line(f"warning: starting without peers {missing} (not alive after "
                           f"{self.readiness.timeout_s:g} s)", err=True)
            now = self.readiness.time_zero(self.clock, self.core.shift_arrivals, self.restarted)
            self._line(f"t={now} started ({len(self.alive)} nodes alive)")
            self.core.start(now)  # ahead of anything that already arrived
            self._started, self._scheduled = True, False
            self._wake_soon()
            self._arm_wake()
            await self._stop.wait()
        finally:
            if self._wake_timer is not None:
                self._wake_timer.cancel()

    @property
    def alive(self) -> set[str]:
        """The nodes of the fleet whose liveliness tokens this node sees now."""
        return self.readiness.alive

    def stop(self) -> None:
        """Make `run()` return (safe to call from signal handlers on the loop)."""
        self._stop_requested = True
        if self._stop is not None:
            self._stop.set()
        self.readiness.stop()

    def statistics(self) -> NodeStatistics:
        """Counters since start, the transport's below the core included, as a frozen record."""
        transport_stats = getattr(self.transport, "statistics", None)  # test doubles may lack it
        if not callable(transport_stats):
            return self.core.statistics()
        below = transport_stats()
        return self.core.statistics(dropped_overflow=below.overflow, refused=below.refused,
                                    external=below.external, played=below.played)

    def idle(self) -> bool:
        """True when nothing can run now: no handler is ready and no drain is scheduled (a
        gated host runs only what is granted), or the node has not started yet."""
        return not self._started or (not self._scheduled and (self._gate is not None
                                                              or not self.core.has_ready()))

    def _declare(self) -> None:
        node, t, fleet = self.node, self.transport, self.fleet
        after_burst = getattr(t, "after_burst", None)
        if after_burst is not None:  # run what a burst of samples brought before the next poll
            after_burst(self._flush)
            self._flushes_bursts = True
        if self._gate is not None:  # before the node token: the coordinator waits for that
            t.serve(node_key(fleet, KeyKind.REPLAY, node.name), self._gate.on_request)
        for spec, topic in self.core.topics():
            t.subscribe(topic_key(fleet, topic), self._deliver(spec.method), spec.qos)
            t.announce(node_key(fleet, KeyKind.SUB, node.name, topic))
        for method, name in self.core.services.items():
            t.serve(topic_key(fleet, name), self._serve(method))
            t.announce(node_key(fleet, KeyKind.SRV, node.name, name))
        if self.fleet_epoch:
            t.watch(kind_expr(fleet, KeyKind.EPOCH), self.readiness.epoch)
        t.watch(kind_expr(fleet, KeyKind.NODE), self._on_liveliness)
        t.announce(node_key(fleet, KeyKind.NODE, node.name))

    # ---------------------------------------------------------------- arrivals

    def _deliver(self, method: str) -> Callable[[str, bytes], None]:
        receive, now_ms, wake = self.core.receiver(method), self.clock.now_ms, self._wake_burst

        def deliver(key: str, payload: bytes) -> None:
            try:
                if receive(payload, now_ms()) and not self._scheduled:
                    wake()
            except DecodeError as exc:  # counted by the core
                if isinstance(exc, Rejected) and exc.first is not None:
                    if exc.first:  # a message of the wrong type: once per sender and topic
                        self._line(str(exc), err=True)
                    return
                self._dropped += 1
                if self._dropped <= _DROP_LINES:  # a flood of bad samples is counted, not logged
                    what = "rejected" if isinstance(exc, Rejected) else "dropped undecodable"
                    more = "; further ones are only counted" if self._dropped == _DROP_LINES else ""
                    self._line(f"{what} sample on {key}: {exc}{more}", err=True)

        return deliver

    def _serve(self, method: str) -> Callable[[bytes, Respond], None]:
        def on_request(payload: bytes, respond: Respond) -> None:
            refused = self.core.receive_request(method, payload, respond, self.clock.now_ms())
            if refused:
                self.perform(refused)
            else:
                self._wake_soon()

        return on_request

    def _on_reply(self, call: int, reply: bytes | None, failure: CallFailure | None,
                  reason: str) -> None:
        if self.core.receive_reply(call, reply, failure, reason, self.clock.now_ms()):
            self._wake_soon()

    def _on_liveliness(self, key: str, alive: bool) -> None:
        name = parse_node_key(key, KeyKind.NODE).node
        self.readiness.node(name, alive)
        if self.core.receive_liveliness(name, alive, self.clock.now_ms()):
            self._wake_soon()

    # ---------------------------------------------------------------- running

    def _schedule_burst(self) -> None:
        """Make sure the core is drained: by the transport's end-of-burst flush if it has one."""
        self._scheduled = True
        if not self._flushes_bursts:
            asyncio.get_running_loop().call_soon(self._drain)

    def _schedule_drain(self) -> None:
        if not self._scheduled:
            self._scheduled = True
            asyncio.get_running_loop().call_soon(self._drain)

    def _flush(self) -> None:
        if self._scheduled and self._started and self.core.has_ready():
            self._drain()  # the call_soon'd drain then finds less (or nothing) to do

    def _drain(self) -> None:
        self._scheduled = False
        run_next, perform, now_ms = self.core.run_next, self.perform, self.clock.now_ms
        for _ in range(_DRAIN_BATCH):
            if self._stop_requested:
                return
            outputs = run_next(now_ms())
            if outputs is None:
                break
            if outputs:
                perform(outputs)
        else:
            if self.core.has_ready():
                self._schedule_drain()
        self._arm_wake()

    def _arm_wake(self) -> None:
        """Keep one clock timer at the core's next due time."""
        due = self.core.next_due()
        if due == self._wake_at:
            return
        if self._wake_timer is not None:
            self._wake_timer.cancel()
        self._wake_at = due
        self._wake_timer = None if due is None else self.clock.call_at(due, self._on_due, due)

    def _on_due(self, due: int) -> None:
        self._wake_at = self._wake_timer = None
        # the clock fired for `due`: that entry is due even if the clock reads a hair earlier
        if self.core.release_due(max(due, self.clock.now_ms())):
            self._wake_soon()
        self._arm_wake()

    def perform(self, outputs: Sequence[Output]) -> None:
        """Carry out a handler's outputs, in the order the core gave them."""
        puts = self._puts
        for out in outputs:
            if type(out) is PublishOutput:  # by far the most frequent: no pattern matching
                put = puts.get(out.topic) or self._publisher(out.topic)
                put(out.payload)
                continue
            match out:
                case CallOutput():
                    wall_ms = self.clock.real_seconds(out.timeout_ms) * 1000.0 + 500.0
                    self.transport.query(topic_key(self.fleet, out.service), out.payload, wall_ms,
                                         functools.partial(self._on_reply, out.call))
                case ReplyOutput(responder=respond, payload=payload, reason=reason):
                    respond(payload, reason)
                case LogOutput(text=text, err=err):
                    self._line(text, err=err)
                case StopOutput():
                    self.failed = True
                    self.stop()

    def _publisher(self, topic: str) -> Callable[[bytes], None]:
        qos = self.publications.get(topic, QOS_DEFAULT)
        put = self._puts[topic] = self.transport.publisher(topic_key(self.fleet, topic), qos)
        self.transport.announce(node_key(self.fleet, KeyKind.PUB, self.node.name, topic))
        return put

    def _line(self, text: str, *, err: bool = False) -> None:
        stream = sys.stderr if err and self.out is sys.stdout else self.out
        print(text, file=stream, flush=True)
