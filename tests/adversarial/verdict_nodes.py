"""Small user-style nodes of the live-verdict tests (importable as
``tests.adversarial.verdict_nodes`` from the project root, as node processes see it)."""

from __future__ import annotations

from dataclasses import dataclass

from twinfleet import Context, Node, every, handler, message, on_start, subscribe
from twinfleet.runtime.contract.node import QoS


@message("twinfleet_test/Blip")
class Blip:
    """One numbered message of a flood."""

    n: int


@dataclass
class CountState:
    """A counter."""

    count: int = 0


@dataclass(frozen=True)
class CounterParams:
    """`fail_at`: raise in the tick that reaches this count (0: never); `misuse_at`:
    publish a plain object there instead, which breaks the node contract."""

    fail_at: int = 0
    misuse_at: int = 0


class Counter(Node):
    """Counts its ticks; raises at `fail_at` (a user's bug)."""

    Params = CounterParams

    def initial_state(self) -> CountState:
        return CountState()

    @every(50)
    def tick(self, ctx: Context) -> None:
        self.state.count += 1
        if self.params.fail_at and self.state.count == self.params.fail_at:
            raise ValueError(f"count reached {self.state.count}")
        if self.params.misuse_at and self.state.count == self.params.misuse_at:
            ctx.publish("/flood", self.state)  # not a registered message


@dataclass(frozen=True)
class FlooderParams:
    """`burst`: messages published by one handler, `bursts`: how many such handlers."""

    burst: int = 3000
    bursts: int = 3


class Flooder(Node):
    """Publishes bounded bursts on /flood (a node of the fleet, so any sender check passes)."""

    Params = FlooderParams

    def initial_state(self) -> CountState:
        return CountState()

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.after(300, self.burst)

    @handler
    def burst(self, ctx: Context) -> None:
        for _ in range(self.params.burst):
            self.state.count += 1
            ctx.publish("/flood", Blip(self.state.count))
        if self.state.count < self.params.burst * self.params.bursts:
            ctx.after(100, self.burst)


class Sink(Node):
    """Needs every /flood message (RELIABLE) but keeps only 5 waiting (KEEP_LAST depth 5)."""

    def initial_state(self) -> CountState:
        return CountState()

    @subscribe("/flood", qos=QoS(depth=5))
    def on_blip(self, ctx: Context, msg: Blip) -> None:
        # ~50 µs of pure work: slower than the flooder publishes, whatever the machine's load
        self.state.count += 1 + 0 * sum(range(1_000))
