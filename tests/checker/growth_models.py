"""Nodes whose state never repeats (a counter never reset, a drifting float) and one whose
counter is bounded, for the state-growth diagnosis. Only the node contract is used."""

from __future__ import annotations

from dataclasses import dataclass, field

from twinfleet import Context, Node, every


@dataclass
class ResetState:
    """State of Resetter and BoundedResetter."""

    resets: int = 0
    phase: int = 0


@dataclass
class HeadingState:
    """State of Drifter."""

    heading: float = 0.0
    turns: list[int] = field(default_factory=list)


class Resetter(Node):
    """Every 10 ms: counts a reset that is never undone, beside a phase that cycles."""

    def initial_state(self) -> ResetState:
        return ResetState()

    @every(10)
    def tick(self, ctx: Context) -> None:
        self.state.resets += 1
        self.state.phase = (self.state.phase + 1) % 4


class BoundedResetter(Node):
    """Like Resetter, but the counter wraps at 100 (a finite state space)."""

    def initial_state(self) -> ResetState:
        return ResetState()

    @every(10)
    def tick(self, ctx: Context) -> None:
        self.state.resets = (self.state.resets + 1) % 100
        self.state.phase = (self.state.phase + 1) % 4


@dataclass(frozen=True)
class DrifterParams:
    """Parameters of Drifter."""

    wobble: bool = True  # choose left or right each time (else always left)


class Drifter(Node):
    """Every 10 ms turns left or right by an irrational-ish step: the heading never repeats."""

    Params = DrifterParams

    def initial_state(self) -> HeadingState:
        return HeadingState()

    @every(10)
    def tick(self, ctx: Context) -> None:
        turn = ctx.choose([1, -1]) if self.params.wobble else 1
        self.state.heading += turn * 0.1 + 0.0123
        self.state.turns = [turn]
