"""Overhead of twinfleet topics over raw zenoh-python: one-way latency and throughput.

Two processes on loopback per measurement pair, started with `subprocess`: an
*echo* process that listens on ``tcp/127.0.0.1:<free port>`` and a *ping*
process that connects to it. Every Zenoh config comes from
`runtime.host.zenoh_transport.zenoh_config`: multicast scouting off, shared memory
off, loopback endpoints only. All implementations share each process's
session (so they share its TCP link and thread placement) and run
**interleaved** inside the pair, because on a small VM the absolute figures
move by 2-4× from one process pair to the next while the ratios within a pair
are stable. Same application payloads (64 B, 4 KiB) for all:

* ``raw`` — plain zenoh-python: the echo side re-puts each ping from its
  subscriber callback; the ping side puts, then blocks on a FIFO channel
  `recv()` for the pong (no loop at all). Floods go to a callback that
  checks sequence numbers.
* ``asyncio`` — raw zenoh-python whose callbacks hand each sample to an
  asyncio loop with `runtime.host.zenoh_transport.Handoff` (what `ZenohTransport`
  does) and act there: the floor of any runtime that runs handlers on a loop,
  as twinfleet's host does (docs/design.md §2). Not a target, a reference.
* ``twinfleet`` — a `NodeHost` per process over `ZenohTransport`, running
  real node classes (`PingNode`, `EchoNode` below): every message goes
  encode → put → Zenoh → hand-off → decode → inbox → `run_handler` → effects.

Latency: ping-pong, one message in flight. Each ping is stamped right before
its `put`, so RTT(n) = stamp(n+1) − stamp(n) covers the full round trip,
including the handler that reacts to pong n; one-way = RTT / 2. Before every
`--chunk` twinfleet rounds the ping node publishes on ``/bench/yield``; the
benchmark's transport wrapper then runs as many raw rounds and asyncio rounds
before letting the node's next ping go (the twinfleet round around each switch
is not counted). The first `--warmup` rounds of each implementation are dropped.

Throughput: the sender publishes back to back (reliable, congestion control
BLOCK) for `--flood-s` (twinfleet: a fixed count, FLOOD_MSGS_PER_S per second of
--flood-s, since node code has no wall clock), then an end marker carrying the count sent; the
receiver checks sequence numbers (gaps, reordering), counts, and answers. Rate
= received / (end marker handled − first sample received), on the receiver.
Twinfleet, raw and asyncio floods alternate, `--floods` of each per pair, after
`--flood-warmup` uncounted floods of each (the first flood of a fresh pair runs
cold: allocator, buffers, specialised bytecode; without the warm-up it fell on
twinfleet alone, which floods first).

Prints a table, one JSON line (``{"summary": ...}``), then a PASS/MISS verdict per
payload size and target (twinfleet latency p50 ≤ 1.3× raw, throughput ≥ 0.7× raw),
each next to the asyncio hand-off floor, which no runtime on a loop can beat.

The anchor: when rclpy is installed (``ros-jazzy-rclpy``, ``ros-jazzy-rmw-fastrtps-cpp``
from the package index), the same run then measures real ROS 2 with the same payloads
(benchmarks/rclpy_anchor.py: its own process pair, rmw_fastrtps, reliable KEEP_LAST 1000)
and prints twinfleet's figures as ratios of rclpy's (``--no-rclpy`` skips it).

    python benchmarks/runtime_overhead.py            # ~1 min: 4 pairs per size
    python benchmarks/runtime_overhead.py --quick    # ~20 s
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import statistics
import struct
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import zenoh  # noqa: E402

from twinfleet import Context, Node, every, handler, message, on_start, subscribe  # noqa: E402
from twinfleet.runtime.contract.messages import decode  # noqa: E402
from twinfleet.runtime.contract.node import QoS  # noqa: E402
from twinfleet.runtime.fleet.launcher import free_port  # noqa: E402
from twinfleet.runtime.host.clock import FleetClock  # noqa: E402
from twinfleet.runtime.host.keys import topic_key  # noqa: E402
from twinfleet.runtime.host.node_host import NodeHost  # noqa: E402
from twinfleet.runtime.host.zenoh_transport import Handoff, ZenohTransport, zenoh_config  # noqa: E402

FLEET = "bench"
RAW = "rawbench"
ASYNC = "asyncbench"
IMPLS = ("raw", "asyncio", "twinfleet")
LATENCY_TARGET = 1.3
THROUGHPUT_TARGET = 0.7
_END = (1 << 64) - 1  # raw end-of-flood marker
_SEQ = struct.Struct("<Q")
_BLOCK = zenoh.CongestionControl.BLOCK
# Reliable and deep enough never to drop a waiting sample (KEEP_LAST with a huge depth ~ KEEP_ALL):
# the receiver falls behind during a flood, and every sample must be handled to be counted.
DEEP = QoS(depth=1 << 20)


# --------------------------------------------------------------------- twinfleet nodes

@message("twinfleet_bench/Data")
class Data:
    """A benchmark sample: a sequence number and an opaque payload (seq -1 ends a flood)."""

    seq: int
    blob: bytes


@message("twinfleet_bench/Done")
class Done:
    """The receiver's answer to an end marker."""

    received: int
    out_of_order: int


@message("twinfleet_bench/Yield")
class Yield:
    """Published by the ping node when the raw implementation should run (`what`)."""

    what: str
    rounds: int


@dataclass(frozen=True)
class PingParams:
    """Parameters of PingNode."""

    size: int = 64
    rounds: int = 2000
    chunk: int = 250
    floods: int = 2
    flood_msgs: int = 30_000
    burst: int = 64


FLOOD_MSGS_PER_S = 60_000  # twinfleet's flood size per second of --flood-s (about its rate)


@dataclass
class PingState:
    """State of PingNode."""

    seq: int = 0
    watched: int = -1
    phase: str = "latency"
    flood_target: int = 0
    floods: int = 0
    sent: int = 0
    done: bool = False


class PingNode(Node):
    """Ping-pong on /bench/ping and /bench/pong, then floods on /bench/flood."""

    Params = PingParams

    def configure(self) -> None:
        self.blob = bytes(self.params.size)

    def initial_state(self) -> PingState:
        return PingState()

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.publish("/bench/yield", Yield("latency", self.params.chunk))
        ctx.publish("/bench/ping", Data(0, self.blob))

    @subscribe("/bench/pong")
    def on_pong(self, ctx: Context, msg: Data) -> None:
        st, p = self.state, self.params
        if st.phase != "latency" or msg.seq != st.seq:
            return  # the answer to a resent ping
        st.seq += 1
        if st.seq < p.rounds:
            if st.seq % p.chunk == 0:  # the raw and asyncio rounds run before the next ping
                ctx.publish("/bench/yield", Yield("latency", p.chunk))
            ctx.publish("/bench/ping", Data(st.seq, self.blob))
        else:
            st.phase = "flood"
            ctx.after(0, self.flood_start)

    @every(200)
    def watchdog(self, ctx: Context) -> None:
        """Resend the first ping if it was put before the echo's subscription was known."""
        st = self.state
        if st.phase == "latency" and st.seq == 0 and st.watched == 0:
            ctx.publish("/bench/ping", Data(0, self.blob))
        st.watched = st.seq

    @handler()
    def flood_start(self, ctx: Context) -> None:
        # A count, not a time: `ctx.now()` of an `after(0)` chain stays at its due time
        # (as in the checker), so node code cannot loop "until" a wall-clock instant.
        self.state.flood_target = self.state.sent + self.params.flood_msgs
        self.flood(ctx)

    @handler()
    def flood(self, ctx: Context) -> None:
        st = self.state
        for _ in range(self.params.burst):
            ctx.publish("/bench/flood", Data(st.sent, self.blob))
            st.sent += 1
        if st.sent < st.flood_target:
            ctx.after(0, self.flood)
        else:
            ctx.publish("/bench/flood", Data(-1, b""))

    @subscribe("/bench/flood_done")
    def on_flood_done(self, ctx: Context, msg: Done) -> None:
        st = self.state
        ctx.publish("/bench/yield", Yield("flood", 0))
        st.floods += 1
        if st.floods < self.params.floods:
            ctx.after(0, self.flood_start)  # after the raw flood that the yield runs
        else:
            st.done = True


@dataclass
class EchoState:
    """State of EchoNode."""

    received: int = 0
    expected: int = -1
    out_of_order: int = 0
    floods: list[tuple[int, int]] = field(default_factory=list)  # (received, out_of_order)


class EchoNode(Node):
    """Answers pings with pongs; counts and checks floods."""

    def initial_state(self) -> EchoState:
        return EchoState()

    @subscribe("/bench/ping", qos=DEEP)
    def on_ping(self, ctx: Context, msg: Data) -> None:
        ctx.publish("/bench/pong", msg)

    @subscribe("/bench/flood", qos=DEEP)
    def on_flood(self, ctx: Context, msg: Data) -> None:
        st = self.state
        if msg.seq < 0:
            st.floods.append((st.received, st.out_of_order))
            ctx.publish("/bench/flood_done", Done(st.received, st.out_of_order))
            st.received, st.out_of_order, st.expected = 0, 0, -1
            return
        if st.expected >= 0 and msg.seq != st.expected:
            st.out_of_order += 1
        st.expected = msg.seq + 1
        st.received += 1


# --------------------------------------------------------------------- raw zenoh-python

class RawPing:
    """The ping side of a raw implementation, on the same session as the twinfleet host.

    ``raw``: puts from the calling thread and blocks on a FIFO channel for the pong.
    ``asyncio``: the pong callback hands the sample to the loop through `Handoff`
    (one wake-up per burst, as `ZenohTransport` does) and the loop puts the next ping.
    Floods are put back to back from the calling thread in both modes.
    """

    def __init__(self, session: zenoh.Session, prefix: str, size: int,
                 handoff: Handoff | None = None) -> None:
        self.handoff = handoff
        if handoff is None:
            self.pongs = session.declare_subscriber(f"{prefix}/pong",
                                                    zenoh.handlers.FifoChannel(64))
        else:
            push, on_pong = handoff.push, self._on_pong
            self.pongs = session.declare_subscriber(
                f"{prefix}/pong", lambda sample: push(on_pong, sample.payload.to_bytes()))
        self.done = session.declare_subscriber(f"{prefix}/flood_done",
                                               zenoh.handlers.FifoChannel(4))
        self.ping = session.declare_publisher(f"{prefix}/ping", congestion_control=_BLOCK)
        self.flood_pub = session.declare_publisher(f"{prefix}/flood", congestion_control=_BLOCK)
        self.pad = bytes(max(0, size - _SEQ.size))
        self.seq = 0
        self.rtt_ns: list[int] = []
        self.sent = 0
        self._left = 0
        self._last = 0
        self._chunk_done: asyncio.Future[None] | None = None

    def rounds(self, n: int) -> None:
        """`n` ping-pong rounds from this thread (raw mode)."""
        last = 0
        for _ in range(n + 1):  # n + 1 stamps give n RTTs
            now = time.perf_counter_ns()
            if last:
                self.rtt_ns.append(now - last)
            last = now
            self.ping.put(_SEQ.pack(self.seq) + self.pad)
            got = _SEQ.unpack_from(self.pongs.recv().payload.to_bytes())[0]
            if got != self.seq:
                raise SystemExit(f"raw pong {got} for ping {self.seq}")
            self.seq += 1

    async def rounds_on_loop(self, n: int) -> None:
        """`n` ping-pong rounds driven by pongs arriving on the loop (asyncio mode)."""
        self._chunk_done = asyncio.get_running_loop().create_future()
        self._left, self._last = n + 1, 0
        self._send()
        await self._chunk_done

    def _send(self) -> None:
        now = time.perf_counter_ns()
        if self._last:
            self.rtt_ns.append(now - self._last)
        self._last = now
        self.ping.put(_SEQ.pack(self.seq) + self.pad)

    def _on_pong(self, payload: bytes) -> None:
        got = _SEQ.unpack_from(payload)[0]
        if got != self.seq:
            raise SystemExit(f"asyncio pong {got} for ping {self.seq}")
        self.seq += 1
        self._left -= 1
        if self._left:
            self._send()
        elif self._chunk_done is not None:
            self._chunk_done.set_result(None)

    def flood(self, seconds: float) -> None:
        """Put back to back for `seconds`, then the end marker; wait for the receiver's answer."""
        until = time.monotonic() + seconds
        sent = 0
        while time.monotonic() < until:
            for _ in range(64):
                self.flood_pub.put(_SEQ.pack(self.sent + sent) + self.pad)
                sent += 1
        self.flood_pub.put(_SEQ.pack(_END) + _SEQ.pack(sent))
        self.sent += sent
        self.done.recv()

    def wait_matching(self, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while not (self.ping.matching_status.matching and self.flood_pub.matching_status.matching):
            if time.monotonic() > deadline:
                raise SystemExit("no raw subscriber matched within the deadline")
            time.sleep(0.01)

    def close(self) -> None:
        for entity in (self.pongs, self.done, self.ping, self.flood_pub):
            entity.undeclare()


class RawEcho:
    """The echo side of a raw implementation: echo pings, count floods.

    ``raw``: in Zenoh's callback threads. ``asyncio``: on the loop, after `Handoff`.
    """

    def __init__(self, session: zenoh.Session, prefix: str, handoff: Handoff | None = None,
                 ) -> None:
        self.pong = session.declare_publisher(f"{prefix}/pong", congestion_control=_BLOCK)
        self.done = session.declare_publisher(f"{prefix}/flood_done", congestion_control=_BLOCK)
        self.floods: list[dict[str, Any]] = []
        self._reset()
        echo, count = self.echo, self.count
        if handoff is None:
            on_ping = lambda sample: echo(sample.payload.to_bytes())  # noqa: E731
            on_flood = lambda sample: count(sample.payload.to_bytes())  # noqa: E731
        else:
            push = handoff.push
            on_ping = lambda sample: push(echo, sample.payload.to_bytes())  # noqa: E731
            on_flood = lambda sample: push(count, sample.payload.to_bytes())  # noqa: E731
        self.subs = [session.declare_subscriber(f"{prefix}/ping", on_ping),
                     session.declare_subscriber(f"{prefix}/flood", on_flood)]

    def _reset(self) -> None:
        self.received, self.expected, self.out_of_order, self.first = 0, -1, 0, 0

    def echo(self, payload: bytes) -> None:
        self.pong.put(payload)

    def count(self, payload: bytes) -> None:
        if not self.first:
            self.first = time.perf_counter_ns()
        (seq,) = _SEQ.unpack_from(payload)
        if seq == _END:
            sent = _SEQ.unpack_from(payload, _SEQ.size)[0]
            self.floods.append(_flood_row(self.received, sent, self.out_of_order,
                                          self.first, time.perf_counter_ns()))
            self._reset()
            self.done.put(b"")
            return
        if self.expected >= 0 and seq != self.expected:
            self.out_of_order += 1
        self.expected = seq + 1
        self.received += 1

    def close(self) -> None:
        for entity in (*self.subs, self.pong, self.done):
            entity.undeclare()


# --------------------------------------------------------------------- the two processes

class Probe:
    """Wraps the ping or echo process's `ZenohTransport` for the host (benchmark plumbing).

    Ping side: stamps twinfleet pings; when the node yields, runs the raw chunk
    right there and holds the node's next ping until the asyncio chunk is done.
    Echo side: stamps the first flood sample and the flood_done answer of each flood.
    """

    def __init__(self, inner: ZenohTransport, raw: RawPing | None = None,
                 on_loop: RawPing | None = None, flood_s: float = 0.0) -> None:
        self.inner, self.raw, self.on_loop, self.flood_s = inner, raw, on_loop, flood_s
        self.ping_key = topic_key(FLEET, "/bench/ping")
        self.yield_key = topic_key(FLEET, "/bench/yield")
        self.flood_key = topic_key(FLEET, "/bench/flood")
        self.done_key = topic_key(FLEET, "/bench/flood_done")
        self.stamps: list[tuple[int, bytes]] = []
        self.first_ns = 0
        self.flood_spans: list[tuple[int, int]] = []
        self._held_rounds = 0
        self._tasks: set[asyncio.Task[None]] = set()

    def put(self, key: str, payload: bytes, qos: Any) -> None:
        if key == self.ping_key:
            if self._held_rounds:
                task = asyncio.get_running_loop().create_task(
                    self._after_loop_rounds(self._held_rounds, key, payload, qos))
                self._tasks.add(task)
                task.add_done_callback(self._tasks.discard)
                self._held_rounds = 0
                return
            self.stamps.append((time.perf_counter_ns(), payload))
        elif key == self.yield_key:
            self._yielded(decode(payload).msg)
            return
        elif key == self.done_key:
            self.flood_spans.append((self.first_ns, time.perf_counter_ns()))
            self.first_ns = 0
        self.inner.put(key, payload, qos)

    def publisher(self, key: str, qos: Any) -> Any:
        """The inner publisher, except for the keys this probe stamps or intercepts."""
        if key in (self.ping_key, self.yield_key, self.done_key):
            return lambda payload: self.put(key, payload, qos)
        return self.inner.publisher(key, qos)

    def _yielded(self, what: Yield) -> None:
        assert self.raw is not None and self.on_loop is not None
        if what.what == "latency":
            self.raw.rounds(what.rounds)
            self._held_rounds = what.rounds
        else:
            self.raw.flood(self.flood_s)
            self.on_loop.flood(self.flood_s)

    async def _after_loop_rounds(self, n: int, key: str, payload: bytes, qos: Any) -> None:
        assert self.on_loop is not None
        await self.on_loop.rounds_on_loop(n)
        self.stamps.append((time.perf_counter_ns(), payload))
        self.inner.put(key, payload, qos)

    def subscribe(self, key: str, deliver: Any, qos: Any) -> None:
        if key != self.flood_key:
            self.inner.subscribe(key, deliver, qos)
            return

        def first(k: str, payload: bytes) -> None:
            if not self.first_ns:
                self.first_ns = time.perf_counter_ns()
            deliver(k, payload)

        self.inner.subscribe(key, first, qos)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)


async def echo_process(args: argparse.Namespace) -> dict[str, Any]:
    transport = ZenohTransport(zenoh_config(listen=[args.endpoint], mode="peer"))
    await transport.open()
    loop = asyncio.get_running_loop()
    raw = RawEcho(transport.session, RAW)
    on_loop = RawEcho(transport.session, ASYNC, Handoff(loop))
    print("READY", flush=True)
    probe = Probe(transport)
    node = EchoNode("echo")
    host = NodeHost(node, probe, FleetClock(args.epoch_ns), seed=1, fleet=FLEET,  # type: ignore[arg-type]
                    out=open(os.devnull, "w"))  # noqa: SIM115
    task = asyncio.create_task(host.run())
    deadline = loop.time() + args.deadline
    try:
        while min(len(node.state.floods), len(raw.floods), len(on_loop.floods)) < args.floods \
                and loop.time() < deadline:
            await asyncio.sleep(0.02)
        await asyncio.sleep(0.3)  # let the last answers leave before closing
    finally:
        host.stop()
        await task
        raw.close()
        on_loop.close()
        await transport.close()
    tf = [_flood_row(received, -1, ooo, first, last)
          for (received, ooo), (first, last) in zip(node.state.floods, probe.flood_spans,
                                                    strict=False)]
    return {"floods": {"raw": raw.floods, "asyncio": on_loop.floods, "twinfleet": tf},
            "gaps": host.statistics().gaps, "undecodable": host.statistics().dropped_undecodable}


async def ping_process(args: argparse.Namespace) -> dict[str, Any]:
    transport = ZenohTransport(zenoh_config(connect=[args.endpoint]))
    await transport.open()
    raw = RawPing(transport.session, RAW, args.size)
    on_loop = RawPing(transport.session, ASYNC, args.size, Handoff(asyncio.get_running_loop()))
    raw.wait_matching(10.0)
    on_loop.wait_matching(10.0)
    probe = Probe(transport, raw, on_loop, args.flood_s)
    params = PingParams(size=args.size, rounds=args.rounds, chunk=args.chunk, floods=args.floods,
                        flood_msgs=max(1000, int(args.flood_s * FLOOD_MSGS_PER_S)))
    node = PingNode("ping", params)
    host = NodeHost(node, probe, FleetClock(args.epoch_ns), seed=1, fleet=FLEET,  # type: ignore[arg-type]
                    wait_for=("echo",), out=open(os.devnull, "w"))  # noqa: SIM115
    task = asyncio.create_task(host.run())
    loop = asyncio.get_running_loop()
    deadline = loop.time() + args.deadline
    try:
        while not node.state.done and loop.time() < deadline:
            await asyncio.sleep(0.01)
    finally:
        host.stop()
        await task
        raw.close()
        on_loop.close()
        await transport.close()
    stamps = [(t, decode(p).msg.seq) for t, p in probe.stamps]
    return {"rtt_ns": {"twinfleet": _rtts(stamps, args.chunk)[args.warmup:],
                       "raw": raw.rtt_ns[args.warmup:], "asyncio": on_loop.rtt_ns[args.warmup:]},
            "sent": {"twinfleet": node.state.sent, "raw": raw.sent, "asyncio": on_loop.sent},
            "done": node.state.done,
            "wire_bytes": {"twinfleet": len(probe.stamps[0][1]) if probe.stamps else 0,
                           "raw": args.size, "asyncio": args.size}}


# --------------------------------------------------------------------- measurement helpers

def _rtts(stamps: list[tuple[int, int]], chunk: int) -> list[int]:
    """RTT of round n: first stamp of seq n+1 minus last stamp of seq n.

    Rounds ending at a chunk boundary (raw rounds ran in between) are left out.
    """
    first: dict[int, int] = {}
    last: dict[int, int] = {}
    for t, seq in stamps:
        first.setdefault(seq, t)
        last[seq] = t
    return [first[s + 1] - last[s] for s in sorted(last)
            if s + 1 in first and (s + 1) % chunk != 0]


def _flood_row(received: int, sent: int, out_of_order: int, first_ns: int,
               last_ns: int) -> dict[str, Any]:
    rate = received / ((last_ns - first_ns) / 1e9) if received and last_ns > first_ns else 0.0
    return {"received": received, "sent": sent, "out_of_order": out_of_order, "msg_per_s": rate}


def _percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))] if ordered else float("nan")


# --------------------------------------------------------------------- orchestration

def child_main(args: argparse.Namespace) -> None:
    """Run one role and print its result as one JSON line."""
    result = asyncio.run(echo_process(args) if args.role == "echo" else ping_process(args))
    print(json.dumps({"role": args.role, **result}), flush=True)


def measure_pair(size: int, opts: argparse.Namespace) -> dict[str, Any]:
    """One process pair: interleaved latency chunks, then alternating floods."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    common = ["--endpoint", endpoint, "--size", str(size), "--rounds", str(opts.rounds),
              "--warmup", str(opts.warmup), "--chunk", str(opts.chunk),
              "--floods", str(opts.floods + opts.flood_warmup), "--flood-s", str(opts.flood_s),
              "--epoch-ns", str(time.time_ns()), "--deadline", str(opts.child_timeout)]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    me = [sys.executable, str(Path(__file__).resolve())]
    procs = [subprocess.Popen([*me, "--role", "echo", *common], stdout=subprocess.PIPE,
                              text=True, env=env, cwd=ROOT)]
    results: dict[str, Any] = {}
    try:
        assert procs[0].stdout is not None
        if procs[0].stdout.readline().strip() != "READY":  # listening: the ping may connect
            raise RuntimeError("echo process did not start")
        procs.append(subprocess.Popen([*me, "--role", "ping", *common], stdout=subprocess.PIPE,
                                      text=True, env=env, cwd=ROOT))
        for proc in reversed(procs):
            out, _ = proc.communicate(timeout=opts.child_timeout + 10)
            lines = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
            if proc.returncode != 0 or not lines:
                raise RuntimeError(f"child exited with {proc.returncode}: {out[-500:]}")
            results[lines[-1]["role"]] = lines[-1]
    finally:
        for proc in procs:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    ping, echo = results["ping"], results["echo"]
    if not ping["done"]:
        raise RuntimeError("the ping node did not finish before its deadline")
    pair: dict[str, Any] = {"size": size}
    for impl in IMPLS:
        one_way = [r / 2000.0 for r in ping["rtt_ns"][impl]]
        floods = echo["floods"][impl]
        counted = floods[opts.flood_warmup:] or floods
        row = {"wire_bytes": ping["wire_bytes"][impl], "rounds": len(one_way),
               "p50_us": _percentile(one_way, 0.5), "p99_us": _percentile(one_way, 0.99),
               "msg_per_s": statistics.median(f["msg_per_s"] for f in counted),
               "sent": ping["sent"][impl], "received": sum(f["received"] for f in floods),
               "out_of_order": sum(f["out_of_order"] for f in floods), "one_way_us": one_way}
        row["lost"] = row["sent"] - row["received"]
        row["gaps"] = echo["gaps"] if impl == "twinfleet" else row["out_of_order"]
        pair[impl] = row
    for impl in ("asyncio", "twinfleet"):
        pair[f"{impl}_latency_ratio"] = pair[impl]["p50_us"] / pair["raw"]["p50_us"]
        pair[f"{impl}_throughput_ratio"] = pair[impl]["msg_per_s"] / pair["raw"]["msg_per_s"]
    return pair


def summarise(pairs: list[dict[str, Any]], sizes: list[int]) -> dict[str, Any]:
    """Pooled latency percentiles, median throughput, and median per-pair ratios per size."""
    summary: dict[str, Any] = {}
    for size in sizes:
        mine = [p for p in pairs if p["size"] == size]
        row: dict[str, Any] = {"pairs": len(mine)}
        for impl in IMPLS:
            one_way = [v for p in mine for v in p[impl]["one_way_us"]]
            row[impl] = {"wire_bytes": mine[0][impl]["wire_bytes"], "rounds": len(one_way),
                         "p50_us": round(_percentile(one_way, 0.5), 1),
                         "p99_us": round(_percentile(one_way, 0.99), 1),
                         "msg_per_s": round(statistics.median(p[impl]["msg_per_s"] for p in mine)),
                         "sent": sum(p[impl]["sent"] for p in mine),
                         "lost": sum(p[impl]["lost"] for p in mine),
                         "gaps": sum(p[impl]["gaps"] for p in mine)}
        for impl in ("asyncio", "twinfleet"):
            for what in ("latency", "throughput"):
                key = f"{impl}_{what}_ratio"
                row[key] = round(statistics.median(p[key] for p in mine), 2)
        row["latency_ok"] = row["twinfleet_latency_ratio"] <= LATENCY_TARGET
        row["throughput_ok"] = row["twinfleet_throughput_ratio"] >= THROUGHPUT_TARGET
        summary[str(size)] = row
    return summary


def print_table(summary: dict[str, Any]) -> None:
    head = (f"{'size':>6} {'impl':<10} {'wire B':>7} {'p50 µs':>8} {'p99 µs':>8} "
            f"{'msg/s':>9} {'× raw lat':>9} {'× raw thr':>9} {'sent':>9} {'lost':>5} {'gaps':>5}")
    print(head)
    print("-" * len(head))
    for size, row in summary.items():
        for impl in IMPLS:
            r = row[impl]
            lat = row.get(f"{impl}_latency_ratio", 1.0)
            thr = row.get(f"{impl}_throughput_ratio", 1.0)
            print(f"{size:>6} {impl:<10} {r['wire_bytes']:>7} {r['p50_us']:>8.1f} "
                  f"{r['p99_us']:>8.1f} {r['msg_per_s']:>9.0f} {lat:>9.2f} {thr:>9.2f} "
                  f"{r['sent']:>9} {r['lost']:>5} {r['gaps']:>5}")
        print(f"{'':>6} twinfleet vs raw (median of {row['pairs']} pairs): latency p50 "
              f"{row['twinfleet_latency_ratio']:.2f}× (target ≤ {LATENCY_TARGET}×: "
              f"{'ok' if row['latency_ok'] else 'MISSED'}), throughput "
              f"{row['twinfleet_throughput_ratio']:.2f}× (target ≥ {THROUGHPUT_TARGET}×: "
              f"{'ok' if row['throughput_ok'] else 'MISSED'})")


def print_verdict(summary: dict[str, Any]) -> None:
    """One PASS/MISS line per payload size and target, with the asyncio floor beside it."""
    print("\nverdict (median of per-pair ratios; the asyncio floor is raw Zenoh + one loop hand-off):")
    for size, row in summary.items():
        checks = (("latency p50", "latency", "≤", LATENCY_TARGET, row["latency_ok"]),
                  ("throughput", "throughput", "≥", THROUGHPUT_TARGET, row["throughput_ok"]))
        for label, what, op, target, ok in checks:
            mine, floor = row[f"twinfleet_{what}_ratio"], row[f"asyncio_{what}_ratio"]
            beyond = (floor > target) if what == "latency" else (floor < target)
            note = "  (target beyond the asyncio floor)" if beyond else ""
            print(f"  {'PASS' if ok else 'MISS'}  {size:>5} B {label:<12} twinfleet {mine:.2f}× raw "
                  f"{op} {target}× target; asyncio floor {floor:.2f}×{note}")


def parent_main(opts: argparse.Namespace) -> None:
    if opts.quick:
        opts.pairs, opts.rounds, opts.floods, opts.flood_s = 2, 1500, 2, 0.4
    sizes = [int(s) for s in opts.sizes.split(",")]
    started = time.monotonic()
    pairs = []
    for _ in range(opts.pairs):
        for size in sizes:
            pair = measure_pair(size, opts)
            pairs.append(pair)
            brief = {k: v for k, v in pair.items() if k not in IMPLS}
            print(json.dumps({"pair": brief}), file=sys.stderr, flush=True)
    summary = summarise(pairs, sizes)
    print_table(summary)
    for p in pairs:
        for impl in IMPLS:
            del p[impl]["one_way_us"]
    print(json.dumps({"summary": summary, "pairs": pairs, "rounds": opts.rounds,
                      "floods": opts.floods, "flood_s": opts.flood_s,
                      "wall_s": round(time.monotonic() - started, 1)}), flush=True)
    print_verdict(summary)
    if not opts.no_rclpy:
        print_rclpy_anchor(summary, sizes, opts)


def print_rclpy_anchor(summary: dict[str, Any], sizes: list[int], opts: argparse.Namespace) -> None:
    """rclpy's latency and flood rate with the same payloads, and twinfleet's as ratios of them."""
    import rclpy_anchor

    if not rclpy_anchor.available():
        print("\nrclpy anchor: rclpy not installed (pip install ros-jazzy-rclpy "
              "ros-jazzy-rmw-fastrtps-cpp), skipped")
        return
    print("\nrclpy anchor (Jazzy, rmw_fastrtps, reliable KEEP_LAST 1000; same payloads, this run):")
    for size in sizes:
        ros = rclpy_anchor.measure(size, rounds=opts.rounds, warmup=opts.warmup,
                                   flood_s=opts.flood_s)
        mine = summary[str(size)]["twinfleet"]
        print(f"  {size:>5} B rclpy one-way p50 {ros['p50_us']:.0f} µs, flood received "
              f"{ros['msg_per_s']:.0f} msg/s ({ros['received']} of {ros['sent']} sent); "
              f"twinfleet p50 {mine['p50_us'] / ros['p50_us']:.2f}× rclpy's, throughput "
              f"{mine['msg_per_s'] / max(ros['msg_per_s'], 1):.1f}× rclpy's", flush=True)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="2 pairs per size, short windows (~20 s)")
    p.add_argument("--pairs", type=int, default=4, help="process pairs per payload size")
    p.add_argument("--sizes", default="64,4096", help="payload sizes in bytes, comma separated")
    p.add_argument("--rounds", type=int, default=2500, help="ping-pong rounds per implementation")
    p.add_argument("--warmup", type=int, default=200, help="first rounds not counted")
    p.add_argument("--chunk", type=int, default=250, help="rounds before switching implementation")
    p.add_argument("--floods", type=int, default=3, help="floods per implementation and pair")
    p.add_argument("--flood-warmup", type=int, default=1,
                   help="uncounted floods of each implementation before the counted ones")
    p.add_argument("--flood-s", type=float, default=0.6, help="seconds per flood")
    p.add_argument("--child-timeout", type=float, default=40.0, help="seconds per process pair")
    p.add_argument("--no-rclpy", action="store_true",
                   help="skip the rclpy anchor (measured when rclpy is installed)")
    p.add_argument("--role", choices=("echo", "ping"), help=argparse.SUPPRESS)
    p.add_argument("--endpoint", help=argparse.SUPPRESS)
    p.add_argument("--size", type=int, default=64, help=argparse.SUPPRESS)
    p.add_argument("--epoch-ns", type=int, default=None, help=argparse.SUPPRESS)
    p.add_argument("--deadline", type=float, default=40.0, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.role:
        child_main(args)
    else:
        parent_main(args)


if __name__ == "__main__":
    main()
