"""`twinfleet calibrate` recovers a latency distribution injected by a test transport."""

from __future__ import annotations

import asyncio
import functools
import random
import subprocess
import sys
from pathlib import Path
from typing import Any

from tests.runtime.hosts import FLEET, Harness, Num, run, settle
from twinfleet import Context, Node, every, subscribe
from twinfleet.checker.timing import load_timing
from twinfleet.runtime.contract.node import QoS
from twinfleet.runtime.core.eventlog import EventLog
from twinfleet.runtime.host.clock import ManualClock
from twinfleet.runtime.host.node_host import NodeHost
from twinfleet.runtime.host.transport import LoopbackBus, LoopbackTransport, key_matches

INJECTED = {0: 0.5, 2: 0.3, 5: 0.2}  # fleet ms: probability


class DelayingTransport:
    """A loopback transport whose every delivery waits a draw from `INJECTED` (fleet ms)."""

    def __init__(self, bus: LoopbackBus, clock: ManualClock, rng: random.Random) -> None:
        self.inner, self.clock, self.rng = LoopbackTransport(bus), clock, rng

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)

    def put(self, key: str, payload: bytes, qos: QoS) -> None:
        for _, pattern, deliver, _ in list(self.inner.bus.subscribers):
            if key_matches(pattern, key):
                delay = self.rng.choices(list(INJECTED), list(INJECTED.values()))[0]
                self.clock.call_at(self.clock.now_ms() + delay, deliver, key, payload)

    def publisher(self, key: str, qos: QoS) -> Any:
        return functools.partial(self.put, key, qos=qos)


class Ticker(Node):
    @every(3)
    def tick(self, ctx: Context) -> None:
        ctx.publish("/nums", Num(1))


class Sink(Node):
    @subscribe("/nums", qos=QoS(depth=100))
    def on_num(self, ctx: Context, msg: Num) -> None:
        pass


def test_calibrate_recovers_an_injected_latency_distribution(tmp_path: Path) -> None:
    log = tmp_path / "sink.events.jsonl"

    async def body() -> None:
        h = Harness()
        rng = random.Random(4)
        for node, events in ((Ticker("ticker"), None),
                             (Sink("sink"), EventLog(str(log), node="sink", time_scale=1.0))):
            transport = DelayingTransport(h.bus, h.clock, rng)
            await transport.open()
            host = NodeHost(node, transport, h.clock, seed=7, fleet=FLEET,  # type: ignore[arg-type]
                            out=h.out, events=events)
            h.hosts.append(host)
            h.tasks.append(asyncio.create_task(host.run()))
            await settle(*h.hosts)
        await h.advance(4500)
        await h.stop()

    run(body(), timeout=120)
    out = tmp_path / "timing.yaml"
    done = subprocess.run([sys.executable, "-m", "twinfleet", "calibrate", str(log), "-o", str(out)],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    model = load_timing(out)
    fitted = model.latency_of("/nums")
    assert fitted.samples >= 1400
    assert set(fitted.values) == set(INJECTED)
    for value, weight in zip(fitted.values, fitted.weights, strict=True):
        assert abs(weight - INJECTED[value]) <= 0.04, (value, weight)  # the stated tolerance
    assert model.time_scale == 1.0
