"""Small systems whose violation probabilities are known by hand (statistical checking)."""

from __future__ import annotations

from dataclasses import dataclass, field

from twinfleet import Context, Node, String, on_start, subscribe


@dataclass
class Pick:
    pick: int = -1


class Coin4(Node):
    """One ctx.choose of four options; option 3 violates: P = 1/4."""

    def initial_state(self) -> Pick:
        return Pick()

    @on_start
    def start(self, ctx: Context) -> None:
        self.state.pick = ctx.choose([0, 1, 2, 3])


class Nested(Node):
    """choose of two, then (on the first) choose of three; (0, 0) violates: P = 1/6."""

    def initial_state(self) -> Pick:
        return Pick()

    @on_start
    def start(self, ctx: Context) -> None:
        if ctx.choose(["a", "b"]) == "a":
            self.state.pick = ctx.choose([0, 1, 2])


class Sender(Node):
    """Publishes one message on /x at start."""

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.publish("/x", String(self.name))


@dataclass
class Times:
    times: list[int] = field(default_factory=list)


class Receiver(Node):
    """Records when each /x message arrived."""

    def initial_state(self) -> Times:
        return Times()

    @subscribe("/x")
    def on_x(self, ctx: Context, msg: String) -> None:
        self.state.times.append(ctx.now())
