"""Nodes for the liveness tests: retry loops over lossy channels, and a real livelock.

Only the node contract is used (no checker imports).
"""

from __future__ import annotations

from dataclasses import dataclass

from tests.checker.models import Num
from twinfleet import (
    CallError,
    Context,
    Node,
    QoS,
    every,
    handler,
    on_start,
    service,
    subscribe,
)


@dataclass
class RetryState:
    """State of Retrier and CallRetrier."""

    done: bool = False


@dataclass(frozen=True)
class RetryParams:
    """Parameters of Retrier: the request it sends (Acker acks only `wanted`)."""

    value: int = 1


class Retrier(Node):
    """Publishes /req every 10 ms until an /ack arrives."""

    Params = RetryParams

    def initial_state(self) -> RetryState:
        return RetryState()

    @on_start
    def start(self, ctx: Context) -> None:
        self.retry(ctx)

    @handler()
    def retry(self, ctx: Context) -> None:
        if not self.state.done:
            ctx.publish("/req", Num(self.params.value))
            ctx.after(10, self.retry)

    @subscribe("/ack")
    def on_ack(self, ctx: Context, msg: Num) -> None:
        self.state.done = True


@dataclass(frozen=True)
class AckerParams:
    """Parameters of Acker."""

    wanted: int = 1


class Acker(Node):
    """Answers a /req carrying `wanted` with an /ack; ignores any other (a livelock when the
    retrier never sends it)."""

    Params = AckerParams

    @subscribe("/req")
    def on_req(self, ctx: Context, msg: Num) -> None:
        if msg.value == self.params.wanted:
            ctx.publish("/ack", Num(msg.value))


class CallRetrier(Node):
    """Calls /add_two (timeout 20 ms) and calls again after every timeout."""

    def initial_state(self) -> RetryState:
        return RetryState()

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.call("/add_two", Num(41), self.on_reply, timeout_ms=20)

    @handler()
    def on_reply(self, ctx: Context, reply: Num | CallError) -> None:
        if isinstance(reply, CallError):
            ctx.call("/add_two", Num(41), self.on_reply, timeout_ms=20)
        else:
            self.state.done = True


class Adder(Node):
    """Serves /add_two."""

    @service("/add_two")
    def add(self, ctx: Context, req: Num) -> Num:
        return Num(req.value + 1)


class Pair(Node):
    """Publishes /m 1 then /m 2 every 10 ms."""

    @every(10)
    def tick(self, ctx: Context) -> None:
        ctx.publish("/m", Num(1))
        ctx.publish("/m", Num(2))


@dataclass
class SeenState:
    """State of KeepLast."""

    got_first: bool = False


class KeepLast(Node):
    """Keeps one waiting /m (KEEP_LAST depth 1): when both wait, the first may be lost."""

    def initial_state(self) -> SeenState:
        return SeenState()

    @subscribe("/m", qos=QoS(depth=1))
    def on_m(self, ctx: Context, msg: Num) -> None:
        if msg.value == 1:
            self.state.got_first = True
