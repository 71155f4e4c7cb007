"""A two-phase commit with timeouts: a coordinator and participants whose decisions hinge
on which of a vote, a decision or a timeout comes first (the user's protocol of issue 37).

A participant that has voted yes gives up (aborts on its own) after `vote_timeout_ms`
without a decision; the coordinator aborts after `decision_timeout_ms` without every
vote. `atomic` breaks when one participant aborts on its own while the others commit.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from twinfleet import Context, Node, String, on_start, subscribe


@dataclass(frozen=True)
class CoordinatorParams:
    """Parameters of Coordinator."""

    participants: int = 2
    decision_timeout_ms: int = 12


@dataclass
class CoordinatorState:
    """State of Coordinator."""

    votes: int = 0
    decision: str = ""


class Coordinator(Node):
    """Asks for votes; commits on every yes, aborts at its timeout."""

    Params = CoordinatorParams

    def initial_state(self) -> CoordinatorState:
        return CoordinatorState()

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.publish("/prepare", String("prepare"))
        ctx.after(self.params.decision_timeout_ms, self.timeout)

    @subscribe("/vote")
    def on_vote(self, ctx: Context, msg: String) -> None:
        self.state.votes += 1
        if self.state.votes == self.params.participants:
            self._decide(ctx, "commit")

    def timeout(self, ctx: Context) -> None:
        self._decide(ctx, "abort")

    def _decide(self, ctx: Context, decision: str) -> None:
        if not self.state.decision:
            self.state.decision = decision
            ctx.publish("/decision", String(decision))


@dataclass(frozen=True)
class ParticipantParams:
    """Parameters of Participant."""

    vote_timeout_ms: int = 8


@dataclass
class ParticipantState:
    """State of Participant."""

    outcome: str = ""


class Participant(Node):
    """Votes yes; takes the decision, or aborts on its own at its timeout."""

    Params = ParticipantParams

    def initial_state(self) -> ParticipantState:
        return ParticipantState()

    @subscribe("/prepare")
    def on_prepare(self, ctx: Context, msg: String) -> None:
        ctx.publish("/vote", String(self.name))
        ctx.after(self.params.vote_timeout_ms, self.give_up)

    def give_up(self, ctx: Context) -> None:
        if not self.state.outcome:
            self.state.outcome = "abort"

    @subscribe("/decision")
    def on_decision(self, ctx: Context, msg: String) -> None:
        if not self.state.outcome:
            self.state.outcome = msg.data


ATOMIC = ("not (coord.decision == 'commit' and "
          "(p1.outcome == 'abort' or p2.outcome == 'abort'))")


def tpc_scenario(folder: Path, name: str = "tpc", *, latency: tuple[int, int] | None = (0, 2),
                 **params: Any) -> Path:
    """Write the two-phase commit of three nodes as a scenario file in `folder` (`params`:
    its common `params:`, e.g. vote_timeout_ms=1)."""
    doc: dict[str, Any] = {
        "name": name, "semantics": "ros",
        "params": {"decision_timeout_ms": 12, "vote_timeout_ms": 8, **params},
        "nodes": [{"name": "coord", "class": "tests.checker.tpc:Coordinator"},
                  {"name": "p1", "class": "tests.checker.tpc:Participant"},
                  {"name": "p2", "class": "tests.checker.tpc:Participant"}],
        "properties": [{"name": "atomic", "kind": "invariant", "expr": ATOMIC}],
        "live": {"wall_timeout_s": 1}}
    if latency is not None:
        doc["check"] = {"latency": list(latency)}
    path = folder / f"{name}.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path
