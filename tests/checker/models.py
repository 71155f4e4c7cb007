"""Tiny node sets whose state spaces are counted by hand in tests/checker.

Only the node contract is used (no checker imports): these are ordinary nodes
that could run live as well.
"""

from __future__ import annotations

from dataclasses import dataclass

from twinfleet import (
    CallError,
    Context,
    Node,
    PureMemo,
    every,
    handler,
    message,
    on_start,
    service,
    subscribe,
)


@message("twinfleet_test/Num")
class Num:
    """An integer payload."""

    value: int = 0


@message("twinfleet_test/Cmd")
class Cmd:
    """A text command."""

    op: str = ""


# --------------------------------------------------------------- ping-pong


@dataclass
class PingState:
    """State of Ping."""

    sent: int = 0


@dataclass(frozen=True)
class PingParams:
    """Parameters of Ping."""

    rounds: int = 3


class Ping(Node):
    """Sends /ping, and again on every /pong until `rounds` pings were sent."""

    Params = PingParams

    def initial_state(self) -> PingState:
        return PingState()

    @on_start
    def start(self, ctx: Context) -> None:
        self.state.sent = 1
        ctx.publish("/ping", Num(1))

    @subscribe("/pong")
    def on_pong(self, ctx: Context, msg: Num) -> None:
        if self.state.sent < self.params.rounds:
            self.state.sent += 1
            ctx.publish("/ping", Num(self.state.sent))


@dataclass
class PongState:
    """State of Pong."""

    received: int = 0


class Pong(Node):
    """Answers every /ping with a /pong."""

    def initial_state(self) -> PongState:
        return PongState()

    @subscribe("/ping")
    def on_ping(self, ctx: Context, msg: Num) -> None:
        self.state.received += 1
        ctx.publish("/pong", Num(msg.value))


# ------------------------------------------------------------------- race


@dataclass(frozen=True)
class OpenerParams:
    """Parameters of Opener."""

    atomic: bool = False


class Opener(Node):
    """Unlocks then opens the door: two messages (racy) or one (atomic)."""

    Params = OpenerParams

    @on_start
    def start(self, ctx: Context) -> None:
        if self.params.atomic:
            ctx.publish("/door", Cmd("unlock_open"))
        else:
            ctx.publish("/door", Cmd("unlock"))
            ctx.publish("/door", Cmd("open"))


class Locker(Node):
    """Locks the door at start."""

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.publish("/door", Cmd("lock"))


@dataclass
class DoorState:
    """State of Door."""

    locked: bool = False
    opened: int = 0


class Door(Node):
    """Fails when asked to open while locked."""

    def initial_state(self) -> DoorState:
        return DoorState()

    @subscribe("/door")
    def on_cmd(self, ctx: Context, cmd: Cmd) -> None:
        if cmd.op == "lock":
            self.state.locked = True
        elif cmd.op == "unlock":
            self.state.locked = False
        elif cmd.op == "unlock_open":
            self.state.locked = False
            self.state.opened += 1
        elif cmd.op == "open":
            if self.state.locked:
                ctx.fail("opened while locked")
            else:
                self.state.opened += 1


# ---------------------------------------------------- sums (ros vs rebeca)


class TwoSender(Node):
    """Publishes 1 then 2 on /add at start (same sender: FIFO under ros)."""

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.publish("/add", Num(1))
        ctx.publish("/add", Num(2))


class FourSender(Node):
    """Publishes 4 on /add4 at start."""

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.publish("/add4", Num(4))


@dataclass
class SumState:
    """State of Summer."""

    total: int = 0


class Summer(Node):
    """Adds what it receives on /add and /add4."""

    def initial_state(self) -> SumState:
        return SumState()

    @subscribe("/add")
    def on_add(self, ctx: Context, msg: Num) -> None:
        self.state.total += msg.value

    @subscribe("/add4")
    def on_add4(self, ctx: Context, msg: Num) -> None:
        self.state.total += msg.value


class UrgentSummer(Summer):
    """Like Summer, but /add4 messages run before simultaneous /add ones."""

    @subscribe("/add4", priority=-1)
    def on_add4(self, ctx: Context, msg: Num) -> None:
        self.state.total += msg.value


@dataclass
class FlagState:
    """State of Flagger."""

    done: bool = False


class Flagger(Node):
    """Sets a flag at t=0 through a zero-delay timer."""

    def initial_state(self) -> FlagState:
        return FlagState()

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.after(0, self.flag)

    @handler()
    def flag(self, ctx: Context) -> None:
        self.state.done = True


class SlowFlagger(Flagger):
    """Like Flagger, but its flag handler has priority 1."""

    @handler(priority=1)
    def flag(self, ctx: Context) -> None:
        self.state.done = True


class Flipper(Flagger):
    """Raises its flag at t=0 and lowers it again 5 ms later."""

    @handler()
    def flag(self, ctx: Context) -> None:
        self.state.done = True
        ctx.after(5, self.lower)

    @handler()
    def lower(self, ctx: Context) -> None:
        self.state.done = False


# ------------------------------------------------- declared commutation


@dataclass(frozen=True)
class ReporterParams:
    """Parameters of Reporter."""

    value: int = 1


class Reporter(Node):
    """Publishes its `value` on /report at start."""

    Params = ReporterParams

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.publish("/report", Num(self.params.value))


class Tally(Node):
    """Adds up the reports: any order gives the same total (declared commutes=True)."""

    def initial_state(self) -> SumState:
        return SumState()

    @subscribe("/report", commutes=True)
    def on_report(self, ctx: Context, msg: Num) -> None:
        self.state.total += msg.value


class Digits(Tally):
    """Declares commutes=True but writes the reports as digits: the order shows."""

    @subscribe("/report", commutes=True)
    def on_report(self, ctx: Context, msg: Num) -> None:
        self.state.total = self.state.total * 10 + msg.value


# ------------------------------------------------------ deadlock, livelock


@dataclass
class WaiterState:
    """State of Waiter."""

    stage: str = "idle"


@dataclass(frozen=True)
class WaiterParams:
    """Parameters of Waiter."""

    inbox: str = "/go_a"
    outbox: str = "/go_b"
    first: bool = False  # send without waiting (breaks the deadlock)


class Waiter(Node):
    """Prepares for 5 ms, then waits for the other's go before sending its own."""

    Params = WaiterParams

    def initial_state(self) -> WaiterState:
        return WaiterState()

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.after(5, self.prepare)

    @handler()
    def prepare(self, ctx: Context) -> None:
        if self.state.stage == "idle":
            self.state.stage = "waiting"
            if self.params.first:
                ctx.publish(self.params.outbox, Cmd("go"))

    def go(self, ctx: Context) -> None:
        """Shared body of the subclasses' subscriptions (topics are fixed per class)."""
        self.state.stage = "done"
        if not self.params.first:
            ctx.publish(self.params.outbox, Cmd("go"))


class WaiterA(Waiter):
    """Waiter listening on /go_a."""

    @subscribe("/go_a")
    def on_go(self, ctx: Context, msg: Cmd) -> None:
        self.go(ctx)


class WaiterB(Waiter):
    """Waiter listening on /go_b."""

    @subscribe("/go_b")
    def on_go(self, ctx: Context, msg: Cmd) -> None:
        self.go(ctx)


@dataclass
class ServerState:
    """State of BallServer."""

    served: bool = False
    scored: bool = False


class BallServer(Node):
    """Serves a ball at 5 ms and returns every ball it gets back: no one ever scores."""

    def initial_state(self) -> ServerState:
        return ServerState()

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.after(5, self.serve)

    @handler()
    def serve(self, ctx: Context) -> None:
        self.state.served = True
        ctx.publish("/ball", Num(0))

    @subscribe("/back")
    def on_back(self, ctx: Context, msg: Num) -> None:
        ctx.publish("/ball", Num(0))


class BallReturner(Node):
    """Returns every ball 10 ms later."""

    @subscribe("/ball")
    def on_ball(self, ctx: Context, msg: Num) -> None:
        ctx.after(10, self.send_back)

    @handler()
    def send_back(self, ctx: Context) -> None:
        ctx.publish("/back", Num(0))


# ----------------------------------------------------------------- choose


@dataclass(frozen=True)
class PickerParams:
    """Parameters of Picker."""

    options: tuple[int, ...] = (10, 20, 30)
    second: tuple[int, ...] = ()  # a second choose() after the first, if non-empty


@dataclass
class PickState:
    """State of Picker."""

    value: int = 0


class Picker(Node):
    """At t=1 picks a value with ctx.choose (and optionally adds a second pick)."""

    Params = PickerParams

    def initial_state(self) -> PickState:
        return PickState()

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.after(1, self.pick)

    @handler()
    def pick(self, ctx: Context) -> None:
        self.state.value = ctx.choose(self.params.options)
        if self.params.second:
            self.state.value += ctx.choose(self.params.second)


# ----------------------------------------------------------------- timers


class TickA(Node):
    """A stateless 100 ms timer."""

    @every(100)
    def tick(self, ctx: Context) -> None:
        pass


class TickB(Node):
    """A stateless 150 ms timer."""

    @every(150)
    def tock(self, ctx: Context) -> None:
        pass


class TickBoth(Node):
    """Both timers on one node (ros fires them in the order they were set)."""

    @every(100)
    def tick(self, ctx: Context) -> None:
        pass

    @every(150)
    def tock(self, ctx: Context) -> None:
        pass


@dataclass(frozen=True)
class CounterParams:
    """Parameters of Counter."""

    period_ms: int = 100
    modulo: int = 3  # 0 = count for ever
    cap: int = 0  # 0 = no cap


@dataclass
class CountState:
    """State of Counter."""

    count: int = 0


class Counter(Node):
    """Counts timer firings, modulo `modulo` or capped at `cap`."""

    Params = CounterParams

    def initial_state(self) -> CountState:
        return CountState()

    @every("period_ms")
    def tick(self, ctx: Context) -> None:
        count = self.state.count + 1
        if self.params.cap:
            count = min(count, self.params.cap)
        if self.params.modulo:
            count %= self.params.modulo
        self.state.count = count


@dataclass
class Looks:
    """The ticks a node counted, and how many it had at t=90 (-1: not yet looked)."""

    ticks: int = 0
    seen: int = -1


class TickCounter(Node):
    """Counts its `@every(20)` ticks until it looks at t=90: four on time (20 to 80),
    fewer for a late node that skipped periods (Rule 7)."""

    def initial_state(self) -> Looks:
        return Looks()

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.after(90, self.look)

    @every(20)
    def tick(self, ctx: Context) -> None:
        if self.state.seen < 0:
            self.state.ticks += 1

    @handler()
    def look(self, ctx: Context) -> None:
        self.state.seen = self.state.ticks


# --------------------------------------------------------------- services


class Adder(Node):
    """Serves /add_two: replies value + 1."""

    @service("/add_two")
    def add(self, ctx: Context, req: Num) -> Num:
        return Num(req.value + 1)


@dataclass(frozen=True)
class ClientParams:
    """Parameters of Client."""

    service: str = "/add_two"


@dataclass
class ClientState:
    """State of Client."""

    result: int = -1
    errors: int = 0


class Client(Node):
    """Calls `service` once at start, timeout 50 ms."""

    Params = ClientParams

    def initial_state(self) -> ClientState:
        return ClientState()

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.call(self.params.service, Num(41), self.on_reply, timeout_ms=50)

    @handler()
    def on_reply(self, ctx: Context, reply: Num | CallError) -> None:
        if isinstance(reply, CallError):
            self.state.errors += 1
        else:
            self.state.result = reply.value


# ------------------------------------------------------------- hygiene


class Sloppy(Node):
    """Keeps a counter outside self.state (a contract violation --debug-state finds)."""

    def configure(self) -> None:
        self.hits = 0

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.after(1, self.bump)

    @handler()
    def bump(self, ctx: Context) -> None:
        self.hits += 1


class SquareCache:
    """A cache of a pure function: its content grows, its answers do not change."""

    def __init__(self) -> None:
        self.known: dict[int, int] = {}

    def square(self, n: int) -> int:
        return self.known.setdefault(n, n * n)


class SquareMemo(SquareCache, PureMemo):
    """The cache declared as a pure memo."""


class Undeclared(SquareCache):
    """The cache with the attribute the checker once read: a magic name declares nothing."""

    pure_memo = True


class Memoising(Node):
    """Keeps a cache beside its state: a `PureMemo` (allowed) or, with `declared=False`,
    an undeclared one that --debug-state reports."""

    @dataclass(frozen=True)
    class Params:
        declared: bool = True

    def configure(self) -> None:
        self.memo = SquareMemo() if self.params.declared else Undeclared()

    def initial_state(self) -> int:
        return 0

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.after(1, self.bump)

    @handler()
    def bump(self, ctx: Context) -> None:
        self.state = self.memo.square(3)


class Crasher(Node):
    """Raises at t=3."""

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.after(3, self.explode)

    @handler()
    def explode(self, ctx: Context) -> None:
        raise RuntimeError("boom")


# ------------------------------------------------ queue bounds, determinism


@dataclass(frozen=True)
class BurstParams:
    """Parameters of Burst."""

    count: int = 3


class Burst(Node):
    """At t=1 publishes `count` messages on /sink at once."""

    Params = BurstParams

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.after(1, self.burst)

    @handler()
    def burst(self, ctx: Context) -> None:
        for k in range(self.params.count):
            ctx.publish("/sink", Num(k))


class Sink(Node):
    """Counts what arrives on /sink."""

    def initial_state(self) -> CountState:
        return CountState()

    @subscribe("/sink")
    def on_msg(self, ctx: Context, msg: Num) -> None:
        self.state.count += 1


class Flaky(Node):
    """Copies a call counter kept outside self.state into its state (a contract violation
    that changes what the handler does, which --check-determinism finds)."""

    def configure(self) -> None:
        self.calls = 0

    def initial_state(self) -> PickState:
        return PickState()

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.after(1, self.tick)

    @handler()
    def tick(self, ctx: Context) -> None:
        self.calls += 1
        self.state.value = self.calls


# ------------------------------------------------------------ faults


@dataclass(frozen=True)
class HeartbeatParams:
    """Parameters of Heartbeat."""

    beats: int = 2


@dataclass
class BeatState:
    """State of Heartbeat and Watchdog."""

    count: int = 0


class Heartbeat(Node):
    """Publishes /beat at t=10, 20, ... (`beats` times)."""

    Params = HeartbeatParams

    def initial_state(self) -> BeatState:
        return BeatState()

    @every(10)
    def beat(self, ctx: Context) -> None:
        if self.state.count < self.params.beats:
            self.state.count += 1
            ctx.publish("/beat", Num(self.state.count))


class Watchdog(Node):
    """Fails if heartbeat k has not arrived when it checks at t = 10k + 5."""

    def initial_state(self) -> BeatState:
        return BeatState()

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.after(15, self.check, 1)

    @subscribe("/beat")
    def on_beat(self, ctx: Context, msg: Num) -> None:
        self.state.count = msg.value

    @handler()
    def check(self, ctx: Context, expected: int) -> None:
        if self.state.count < expected:
            ctx.fail(f"heartbeat {expected} missing at t={ctx.now()}")
        elif expected < 2:
            ctx.after(10, self.check, expected + 1)
