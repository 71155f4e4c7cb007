"""Demo-like nodes of the reliability tests (liveliness, network cuts, soak, fuzzing).

Importable as ``tests.integration.reliability_nodes`` from the project root,
which is what the node processes started by the launcher see.
"""

from __future__ import annotations

import gc
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path

from twinfleet import Context, Node, String, every, message, service, subscribe
from twinfleet.runtime.contract.messages import NodeAlive
from twinfleet.runtime.contract.node import QOS_SENSOR_DATA, QoS


@message("twinfleet_test/FleetStatus")
class FleetStatus:
    """Which watched nodes are alive, and how often each was lost."""

    alive: tuple[str, ...]
    lost: tuple[str, ...]
    losses: int


@message("twinfleet_test/Tick")
class Tick:
    """A numbered sample of a soak publisher."""

    source: str
    n: int
    blob: bytes = b""


@message("twinfleet_test/AddRequest")
class AddRequest:
    """Request of the `/fuzz/add` service."""

    a: int
    b: int


@message("twinfleet_test/AddReply")
class AddReply:
    """Reply of the `/fuzz/add` service."""

    total: int


@dataclass(frozen=True)
class HeartbeatParams:
    """Parameters of Heartbeat."""

    period_ms: int = 100


@dataclass
class HeartbeatState:
    """State of Heartbeat."""

    beats: int = 0


class Heartbeat(Node):
    """A robot stand-in: publishes its name on `/heartbeat` every `period_ms`."""

    Params = HeartbeatParams

    def initial_state(self) -> HeartbeatState:
        return HeartbeatState()

    @every("period_ms")
    def beat(self, ctx: Context) -> None:
        self.state.beats += 1
        ctx.publish("/heartbeat", String(self.name))


@dataclass(frozen=True)
class WatcherParams:
    """Parameters of Watcher."""

    watch: tuple[str, ...] = ()


@dataclass
class WatcherState:
    """State of Watcher."""

    alive: tuple[str, ...] = ()
    losses: int = 0
    heard: int = 0


class Watcher(Node):
    """A map-server stand-in: notices nodes appearing and disappearing (liveliness).

    Logs ``alive node=...`` / ``lost node=...`` / ``back node=...`` and publishes
    the fleet status on `/fleet_status` at every change.
    """

    Params = WatcherParams

    def initial_state(self) -> WatcherState:
        return WatcherState()

    @subscribe("/_liveliness")
    def on_liveliness(self, ctx: Context, msg: NodeAlive) -> None:
        st = self.state
        if msg.name not in self.params.watch:
            return
        was_alive = msg.name in st.alive
        if msg.alive and not was_alive:
            st.alive = tuple(sorted((*st.alive, msg.name)))
            ctx.log("back" if st.losses else "alive", node=msg.name)
        elif not msg.alive and was_alive:
            st.alive = tuple(n for n in st.alive if n != msg.name)
            st.losses += 1
            ctx.log("lost", node=msg.name)
        else:
            return
        lost = tuple(n for n in self.params.watch if n not in st.alive)
        ctx.publish("/fleet_status", FleetStatus(st.alive, lost, st.losses))

    @subscribe("/heartbeat")
    def on_heartbeat(self, ctx: Context, msg: String) -> None:
        self.state.heard += 1
        if self.state.heard % 10 == 1:
            ctx.log("heard", sender=msg.data, total=self.state.heard)


@dataclass(frozen=True)
class FloodParams:
    """Parameters of Flood."""

    period_ms: int = 10
    burst: int = 20
    size: int = 64
    limit: int = 0  # stop after this many samples per topic (0 = never)
    rounds: int = 1  # split `limit` into rounds; the next starts when the sink says `/soak/next`


@dataclass
class FloodState:
    """State of Flood."""

    sent: int = 0
    rounds_open: int = 1  # rounds the sink has let start


class Flood(Node):
    """A soak publisher: `burst` samples every `period_ms`, on a reliable and a best-effort topic."""

    Params = FloodParams
    publications = {"/soak/fast": QOS_SENSOR_DATA}

    def configure(self) -> None:
        self.blob = bytes(self.params.size)

    def initial_state(self) -> FloodState:
        return FloodState()

    @every("period_ms")
    def burst(self, ctx: Context) -> None:
        st, p = self.state, self.params
        cap = p.limit * st.rounds_open // p.rounds if p.limit else 0
        for _ in range(p.burst):
            if cap and st.sent >= cap:
                return
            st.sent += 1
            ctx.publish("/soak/reliable", Tick(self.name, st.sent, self.blob))
            ctx.publish("/soak/fast", Tick(self.name, st.sent, self.blob))

    @subscribe("/soak/next")
    def on_next(self, ctx: Context, msg: String) -> None:
        self.state.rounds_open = max(self.state.rounds_open, int(msg.data))


@dataclass(frozen=True)
class SinkParams:
    """Parameters of Sink."""

    expected: int = 0  # reliable samples to receive before asking the launcher to stop
    rounds: int = 1  # the publishers' rounds: after each, measure memory and open the next


@dataclass
class SinkState:
    """State of Sink."""

    reliable: int = 0
    fast: int = 0
    out_of_order: int = 0
    first_ms: int = -1
    last_ms: int = -1
    done: bool = False
    last: dict[str, int] = field(default_factory=dict)


def memory_now() -> dict[str, int]:
    """This process's resident set (kB) and live Python objects (pymalloc blocks, after a
    collection): the second does not depend on how much memory a backlog once took."""
    gc.collect()
    status = Path("/proc/self/status").read_text()
    rss = re.search(r"^VmRSS:\s+(\d+) kB", status, re.M)
    return {"rss_kb": int(rss.group(1)) if rss else -1, "blocks": sys.getallocatedblocks()}


class Sink(Node):
    """The soak subscriber: counts both topics and checks per-source order on the reliable one.

    At the end of each of the publishers' rounds it logs ``round_done`` with its memory
    (`memory_now`) and publishes the next round's number on ``/soak/next``; once
    `expected` reliable samples arrived, it logs ``soak_done`` and publishes on
    ``/twinfleet/shutdown``.
    """

    Params = SinkParams

    def initial_state(self) -> SinkState:
        return SinkState()

    @subscribe("/soak/reliable", qos=QoS(depth=100_000))
    def on_reliable(self, ctx: Context, msg: Tick) -> None:
        st, p = self.state, self.params
        if msg.n != st.last.get(msg.source, 0) + 1:
            st.out_of_order += 1
        st.last[msg.source] = msg.n
        st.reliable += 1
        if st.first_ms < 0:
            st.first_ms = ctx.now()
        st.last_ms = ctx.now()
        finished, rest = divmod(st.reliable * p.rounds, p.expected) if p.expected else (0, 1)
        if not rest and finished:  # the last sample of a round: nothing of it is waiting
            ctx.log("round_done", round=finished, **memory_now())
            if finished < p.rounds:
                ctx.publish("/soak/next", String(str(finished + 1)))
        if st.reliable == p.expected and not st.done:
            st.done = True
            ctx.log("soak_done", reliable=st.reliable, fast=st.fast, out_of_order=st.out_of_order,
                    first_ms=st.first_ms, last_ms=st.last_ms)
            ctx.publish("/twinfleet/shutdown", String("soak done"))

    @subscribe("/soak/fast", qos=QoS(QOS_SENSOR_DATA.reliability, depth=100_000))
    def on_fast(self, ctx: Context, msg: Tick) -> None:
        self.state.fast += 1

    @every(1000)
    def report(self, ctx: Context) -> None:
        st = self.state
        ctx.log("soak", reliable=st.reliable, fast=st.fast, out_of_order=st.out_of_order)


@dataclass
class TargetState:
    """State of FuzzTarget."""

    good: int = 0
    calls: int = 0


class FuzzTarget(Node):
    """What the fuzz tests throw garbage at: a typed subscription and a typed service."""

    def initial_state(self) -> TargetState:
        return TargetState()

    @subscribe("/fuzz/ticks", qos=QoS(depth=10_000))  # every sample runs: counts are exact
    def on_tick(self, ctx: Context, msg: Tick) -> None:
        self.state.good += msg.n - msg.n + 1  # raises on a message whose `n` is not a number

    @service("/fuzz/add")
    def add(self, ctx: Context, req: AddRequest) -> AddReply:
        self.state.calls += 1
        return AddReply(req.a + req.b)
