"""Shared by the host tests: nodes, and hosts on one loopback bus with one manual clock."""

from __future__ import annotations

import asyncio
import io
from collections.abc import Coroutine
from dataclasses import dataclass, field
from typing import Any

from twinfleet import (
    CallError,
    Context,
    Node,
    every,
    handler,
    message,
    on_start,
    service,
    subscribe,
)
from twinfleet.runtime.contract.node import QoS, Reliability
from twinfleet.runtime.host.clock import ManualClock
from twinfleet.runtime.host.node_host import NodeHost
from twinfleet.runtime.host.transport import LoopbackBus, LoopbackTransport

FLEET = "t"


@message("test_msgs/Num")
class Num:
    value: int


@dataclass
class Log:
    seen: list[Any] = field(default_factory=list)


class Recorder(Node):
    """Records (time, event) pairs; two timers with different priorities; an `after` chain."""

    def initial_state(self) -> Log:
        return Log()

    @on_start
    def start(self, ctx: Context) -> None:
        self.state.seen.append((ctx.now(), "start"))
        ctx.after(50, self.later, "x")

    @handler(priority=3)
    def later(self, ctx: Context, tag: str) -> None:
        self.state.seen.append((ctx.now(), f"later {tag}"))

    @every(100, priority=2)
    def slow_tick(self, ctx: Context) -> None:
        self.state.seen.append((ctx.now(), "tick p2"))

    @every(100, priority=1)
    def fast_tick(self, ctx: Context) -> None:
        self.state.seen.append((ctx.now(), "tick p1"))

    @subscribe("/low", priority=5)
    def on_low(self, ctx: Context, msg: Num) -> None:
        self.state.seen.append((ctx.now(), f"low {msg.value}"))

    @subscribe("/high", priority=0)
    def on_high(self, ctx: Context, msg: Num) -> None:
        self.state.seen.append((ctx.now(), f"high {msg.value}"))


class Shallow(Node):
    """Keeps at most three waiting messages per subscription (KEEP_LAST depth 3)."""

    def initial_state(self) -> Log:
        return Log()

    @subscribe("/nums", qos=QoS(depth=3))
    def on_num(self, ctx: Context, msg: Num) -> None:
        self.state.seen.append(msg.value)

    @subscribe("/other", qos=QoS(Reliability.BEST_EFFORT, depth=1))
    def on_other(self, ctx: Context, msg: Num) -> None:
        self.state.seen.append(-msg.value)


class Doubler(Node):
    """Serves /double; raises for negative input; `ctx.fail` for 13."""

    @service("/double")
    def double(self, ctx: Context, req: Num) -> Num:
        if req.value < 0:
            raise ValueError("negative")
        if req.value == 13:
            ctx.fail("unlucky number")
        return Num(req.value * 2)


@dataclass(frozen=True)
class AskerParams:
    service: str = "/double"
    value: int = 21
    timeout_ms: int = 200


class Asker(Node):
    """Calls a service once at start and records the reply."""

    Params = AskerParams

    def initial_state(self) -> Log:
        return Log()

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.call(self.params.service, Num(self.params.value), self.on_reply,
                 timeout_ms=self.params.timeout_ms)

    @handler()
    def on_reply(self, ctx: Context, reply: Num | CallError) -> None:
        self.state.seen.append(reply)


def run(coro: Coroutine[Any, Any, Any], timeout: float = 10.0) -> Any:
    """Run a test coroutine with a deadline."""
    return asyncio.run(asyncio.wait_for(coro, timeout))


async def settle(*hosts: NodeHost, rounds: int = 2000) -> None:
    """Let the loop run until every host is idle for a few iterations in a row."""
    streak = 0
    for _ in range(rounds):
        await asyncio.sleep(0)
        streak = streak + 1 if all(h.idle() for h in hosts) else 0
        if streak >= 10:
            return
    raise AssertionError("hosts did not settle")


class Harness:
    """Hosts on one loopback bus and one manual clock."""

    def __init__(self) -> None:
        self.bus = LoopbackBus()
        self.clock = ManualClock()
        self.hosts: list[NodeHost] = []
        self.tasks: list[asyncio.Task[None]] = []
        self.out = io.StringIO()

    async def start(self, node: Node, **kw: Any) -> NodeHost:
        transport = LoopbackTransport(self.bus)
        await transport.open()
        host = NodeHost(node, transport, self.clock, seed=7, fleet=FLEET, out=self.out, **kw)
        self.hosts.append(host)
        self.tasks.append(asyncio.create_task(host.run()))
        await settle(*self.hosts)
        return host

    async def raw(self) -> LoopbackTransport:
        transport = LoopbackTransport(self.bus)
        await transport.open()
        return transport

    async def advance(self, ms: int) -> None:
        """Advance in steps, letting the hosts run between due times (as live time would)."""
        target = self.clock.now_ms() + ms
        while (due := self.clock.next_due()) is not None and due <= target:
            self.clock.advance(due - self.clock.now_ms())
            await settle(*self.hosts)
        self.clock.advance(target - self.clock.now_ms())
        await settle(*self.hosts)

    async def stop(self) -> None:
        for host in self.hosts:
            host.stop()
        await asyncio.gather(*self.tasks)
