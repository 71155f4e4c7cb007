"""One tiny node system per feature of the node contract, for the conformance suite.

Each system ends its own live run: a node publishes a `String` on
`/twinfleet/shutdown` when its part is done (the launcher ends the run; in the
checker nobody subscribes, so the publish adds nothing). Every state is a
small dataclass, so the properties of `test_conformance` can read it.
"""

from __future__ import annotations

from dataclasses import dataclass

from twinfleet import (
    QOS_LATCHED,
    QOS_SENSOR_DATA,
    CallError,
    Context,
    Node,
    QoS,
    String,
    every,
    handler,
    message,
    on_start,
    service,
    subscribe,
)
from twinfleet.runtime.contract.messages import NodeAlive
from twinfleet.runtime.contract.node import LIVELINESS_TOPIC

SHUTDOWN = "/twinfleet/shutdown"
END_MS = 60  # fleet ms after its last action at which a system asks the run to end


@message("conformance/Num")
@dataclass(frozen=True)
class Num:
    value: int


@dataclass
class Heard:
    """What a receiving node saw, in order."""

    seen: tuple[int, ...] = ()
    count: int = 0


def stop_later(ctx: Context, node: Node) -> None:
    """End the live run `END_MS` after now."""
    ctx.after(END_MS, node.stop)  # type: ignore[attr-defined]


class Ender(Node):
    """A node that can end the run (`stop`)."""

    @handler()
    def stop(self, ctx: Context) -> None:
        ctx.publish(SHUTDOWN, String(f"{self.name} done"))


class Delayed(Ender):
    """Acts once (`act`) at t=10."""

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.after(10, self.act)

    @handler()
    def act(self, ctx: Context) -> None:
        raise NotImplementedError


# ------------------------------------------------------------------ pub/sub, QoS


@dataclass(frozen=True)
class TalkerParams:
    topic: str = "/chat"
    burst: int = 1  # messages per round, published in one handler
    rounds: int = 3
    period_ms: int = 10


class Talker(Ender):
    """Publishes `burst` numbered messages on `topic` per round, `rounds` rounds."""

    Params = TalkerParams

    def initial_state(self) -> int:
        return 0

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.after(self.params.period_ms, self.talk)

    @handler()
    def talk(self, ctx: Context) -> None:
        for _ in range(self.params.burst):
            self.state += 1
            ctx.publish(self.params.topic, Num(self.state))
        if self.state < self.params.rounds * self.params.burst:
            ctx.after(self.params.period_ms, self.talk)
        else:
            stop_later(ctx, self)


class Listener(Node):
    """Records every number heard on /chat."""

    def initial_state(self) -> Heard:
        return Heard()

    @subscribe("/chat")
    def on_chat(self, ctx: Context, msg: Num) -> None:
        self.state.seen += (msg.value,)
        self.state.count += 1


class Shallow(Listener):
    """Listener with KEEP_LAST depth 2 on /chat."""

    @subscribe("/chat", qos=QoS(depth=2))
    def on_chat(self, ctx: Context, msg: Num) -> None:
        super().on_chat(ctx, msg)


class Lossy(Listener):
    """Listener whose subscription is BEST_EFFORT (sensor data QoS, depth 5)."""

    @subscribe("/chat", qos=QOS_SENSOR_DATA)
    def on_chat(self, ctx: Context, msg: Num) -> None:
        super().on_chat(ctx, msg)


class Latched(Listener):
    """Listener whose subscription is TRANSIENT_LOCAL (latched)."""

    @subscribe("/chat", qos=QOS_LATCHED)
    def on_chat(self, ctx: Context, msg: Num) -> None:
        super().on_chat(ctx, msg)


# ------------------------------------------------------------------ priorities


class TwoTopics(Delayed):
    """Publishes /low then /high in one handler."""

    @handler()
    def act(self, ctx: Context) -> None:
        ctx.publish("/low", Num(1))
        ctx.publish("/high", Num(2))
        stop_later(ctx, self)


class Prioritised(Node):
    """/high (priority 0) runs before /low (priority 5) when both wait at one time."""

    def initial_state(self) -> Heard:
        return Heard()

    @subscribe("/low", priority=5)
    def on_low(self, ctx: Context, msg: Num) -> None:
        self.state.seen += (msg.value,)

    @subscribe("/high", priority=0)
    def on_high(self, ctx: Context, msg: Num) -> None:
        self.state.seen += (msg.value,)


# ------------------------------------------------------------------ services


@dataclass
class Replies:
    answers: tuple[int, ...] = ()
    errors: tuple[str, ...] = ()


class Doubler(Node):
    """Serves /double."""

    @service("/double")
    def double(self, ctx: Context, req: Num) -> Num:
        return Num(req.value * 2)


class Client(Delayed):
    """Calls /double (served) and /absent (no server: its call times out)."""

    def initial_state(self) -> Replies:
        return Replies()

    @handler()
    def act(self, ctx: Context) -> None:
        # Long enough for a server that a loaded machine slows down to a few hundred ms: a
        # live timeout here would be a path the checker rightly cannot explain.
        ctx.call("/double", Num(21), self.on_reply, timeout_ms=2_000)
        ctx.call("/absent", Num(1), self.on_reply, timeout_ms=30)

    @handler()
    def on_reply(self, ctx: Context, reply: Num | CallError) -> None:
        if isinstance(reply, CallError):
            self.state.errors += (reply.service,)
        else:
            self.state.answers += (reply.value,)
        if len(self.state.answers) + len(self.state.errors) == 2:
            stop_later(ctx, self)


# ------------------------------------------------------------------ timers


@dataclass
class Ticks:
    at: tuple[int, ...] = ()
    args: tuple[int, ...] = ()


class Chain(Ender):
    """A chain of `ctx.after` timers with an argument: 3 steps, 7 ms apart."""

    def initial_state(self) -> Ticks:
        return Ticks()

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.after(7, self.step, 1)

    @handler()
    def step(self, ctx: Context, n: int) -> None:
        self.state.at += (ctx.now(),)
        self.state.args += (n,)
        if n < 3:
            ctx.after(7, self.step, n + 1)
        else:
            stop_later(ctx, self)


class Ticker(Ender):
    """An `@every(20, phase_ms=5)` timer that stops the run after 3 ticks."""

    def initial_state(self) -> Ticks:
        return Ticks()

    @every(20, phase_ms=5)
    def tick(self, ctx: Context) -> None:
        if len(self.state.at) < 3:
            self.state.at += (ctx.now(),)
            if len(self.state.at) == 3:
                stop_later(ctx, self)


# ------------------------------------------------------------------ start handlers


@dataclass
class Started:
    order: tuple[str, ...] = ()


class TwoStarts(Ender):
    """Two `@on_start` handlers (run in declaration order) and a message from a peer."""

    def initial_state(self) -> Started:
        return Started()

    @on_start
    def first(self, ctx: Context) -> None:
        self.state.order += ("first",)

    @on_start
    def second(self, ctx: Context) -> None:
        self.state.order += ("second",)
        stop_later(ctx, self)

    @subscribe("/hello")
    def on_hello(self, ctx: Context, msg: String) -> None:
        self.state.order += ("hello",)


class Greeter(Node):
    """Publishes /hello from its `@on_start`."""

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.publish("/hello", String("hi"))


# ------------------------------------------------------------------ exceptions


class Fragile(Listener):
    """Changes its state, then raises, on the message numbered 2: the change is rolled back."""

    @subscribe("/chat")
    def on_chat(self, ctx: Context, msg: Num) -> None:
        super().on_chat(ctx, msg)
        if msg.value == 2:
            ctx.publish("/never", Num(0))  # cleared with the rest of the handler's effects
            raise ValueError("two is unlucky")


class NeverHeard(Listener):
    """Listens on /never, which only a failed handler published."""

    @subscribe("/never")
    def on_chat(self, ctx: Context, msg: Num) -> None:
        super().on_chat(ctx, msg)


# ------------------------------------------------------------------ liveliness


@dataclass
class Alive:
    seen: tuple[tuple[str, bool], ...] = ()


class Onlooker(Node):
    """Records every liveliness change it is told about."""

    def initial_state(self) -> Alive:
        return Alive()

    @subscribe(LIVELINESS_TOPIC)
    def on_alive(self, ctx: Context, msg: NodeAlive) -> None:
        self.state.seen += ((msg.name, msg.alive),)


class Watcher(Onlooker, Ender):
    """An onlooker that ends the run at t=60."""

    @on_start
    def start(self, ctx: Context) -> None:
        stop_later(ctx, self)


class Quiet(Node):
    """A node that only exists."""


# ------------------------------------------------------------------ crash and restart


class Counter(Node):
    """Counts its ticks up to 5 and publishes each count on /count (its state is reset
    when it crashes: it counts again from 1 after a restart)."""

    def initial_state(self) -> int:
        return 0

    @every(200)
    def tick(self, ctx: Context) -> None:
        if self.state < 5:
            self.state += 1
            ctx.publish("/count", Num(self.state))


@dataclass
class Heard5:
    last: int = 0
    restarted: bool = False  # a count that did not go up: the counter started afresh
    done: bool = False


class Boss(Ender):
    """Ends the run once the counter, restarted, has counted to 5."""

    def initial_state(self) -> Heard5:
        return Heard5()

    @subscribe("/count")
    def on_count(self, ctx: Context, msg: Num) -> None:
        s = self.state
        s.restarted = s.restarted or msg.value <= s.last
        s.last = msg.value
        if msg.value == 5 and s.restarted and not s.done:
            s.done = True
            stop_later(ctx, self)
