"""A small demo fleet: a talker, a listener, an adder service and its caller.

It exercises every part of the node contract (topics, a service, a periodic
timer, `ctx.after`, `ctx.choose`) and is what `launch/demo.yaml` runs.
"""

from __future__ import annotations

from dataclasses import dataclass

from twinfleet import (
    CallError,
    Context,
    Node,
    String,
    every,
    handler,
    message,
    on_start,
    service,
    subscribe,
)


@message("example_interfaces/AddTwoInts_Request")
class AddRequest:
    """Request of the `add_two_ints` service."""

    a: int
    b: int


@message("example_interfaces/AddTwoInts_Response")
class AddReply:
    """Reply of the `add_two_ints` service."""

    sum: int


@dataclass(frozen=True)
class TalkerParams:
    """Parameters of Talker."""

    period_ms: int = 100
    limit: int = 0  # stop after this many messages (0 = never)


@dataclass
class TalkerState:
    """State of Talker."""

    count: int = 0


class Talker(Node):
    """Publishes `/chatter` every `period_ms` ms, `limit` times (0 = for ever)."""

    Params = TalkerParams

    def initial_state(self) -> TalkerState:
        return TalkerState()

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.after(self.params.period_ms, self.tick)

    @handler(priority=1)
    def tick(self, ctx: Context) -> None:
        self.state.count += 1
        ctx.publish("/chatter", String(f"hello {self.state.count}"))
        if self.params.limit == 0 or self.state.count < self.params.limit:
            ctx.after(self.params.period_ms, self.tick)


@dataclass
class ListenerState:
    """State of Listener."""

    heard: int = 0
    last: str = ""


class Listener(Node):
    """Counts what it hears on `chatter`."""

    def initial_state(self) -> ListenerState:
        return ListenerState()

    @subscribe("/chatter")
    def on_chatter(self, ctx: Context, msg: String) -> None:
        self.state.heard += 1
        self.state.last = msg.data
        ctx.log("heard", data=msg.data)


class Adder(Node):
    """Serves `add_two_ints`."""

    @service("/add_two_ints")
    def add(self, ctx: Context, req: AddRequest) -> AddReply:
        return AddReply(req.a + req.b)


@dataclass(frozen=True)
class CallerParams:
    """Parameters of Caller."""

    period_ms: int = 500
    timeout_ms: int = 1000
    service: str = "/add_two_ints"


@dataclass
class CallerState:
    """State of Caller."""

    calls: int = 0
    replies: int = 0
    errors: int = 0
    last_sum: int = -1


class Caller(Node):
    """Calls `add_two_ints` periodically with operands picked by `ctx.choose`."""

    Params = CallerParams

    def initial_state(self) -> CallerState:
        return CallerState()

    @every("period_ms")
    def tick(self, ctx: Context) -> None:
        self.state.calls += 1
        a = ctx.choose((1, 2, 3))
        ctx.call(self.params.service, AddRequest(a, 10), self.on_sum, timeout_ms=self.params.timeout_ms)

    @handler()
    def on_sum(self, ctx: Context, reply: AddReply | CallError) -> None:
        if isinstance(reply, CallError):
            self.state.errors += 1
            ctx.log("call_failed", reason=reply.reason)
            return
        self.state.replies += 1
        self.state.last_sum = reply.sum
        ctx.log("sum", value=reply.sum)


@dataclass(frozen=True)
class CrasherParams:
    """Parameters of Crasher."""

    crash_after_ms: int = 300


class Crasher(Node):
    """Raises in a handler after `crash_after_ms`: with `live.stop_on_error` the node dies."""

    Params = CrasherParams

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.after(self.params.crash_after_ms, self.explode)

    @handler()
    def explode(self, ctx: Context) -> None:
        raise RuntimeError("deliberate crash for testing")
