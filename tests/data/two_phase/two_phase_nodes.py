"""A two-phase commit: a coordinator and participants, with timeouts and retries.

The coordinator asks every participant to prepare, collects their votes and
announces commit (every vote yes) or abort (a vote no, or no answer from some
participant after its retries), then repeats its decision until every
participant acknowledged it. A participant votes when asked (again when asked
again), and repeats its vote while no decision came. Over a network with
0-2 ms of latency the timeouts race the messages, so the same protocol run has
many interleavings: a workload where the partial-order reduction has little to
prune (every message crosses between two nodes, and the properties read them
all).
"""

from __future__ import annotations

from dataclasses import dataclass

from twinfleet import Context, Node, handler, message, on_start, subscribe


@message("two_phase/Prepare")
class Prepare:
    attempt: int


@message("two_phase/Vote")
class Vote:
    participant: str
    yes: bool


@message("two_phase/Decision")
class Decision:
    commit: bool


@message("two_phase/Ack")
class Ack:
    participant: str


@dataclass(frozen=True)
class CoordinatorParams:
    """Who takes part, and the coordinator's patience."""

    participants: tuple[str, ...] = ("p1", "p2", "p3")
    vote_timeout_ms: int = 4
    ack_timeout_ms: int = 4
    retries: int = 1


@dataclass
class CoordinatorState:
    phase: str = "voting"  # voting, deciding, done
    attempt: int = 0
    yes: tuple[str, ...] = ()
    commit: bool = False
    acked: tuple[str, ...] = ()
    resent: int = 0


class Coordinator(Node):
    """Prepares, decides, and repeats the decision until every participant acknowledged."""

    Params = CoordinatorParams

    def initial_state(self) -> CoordinatorState:
        return CoordinatorState()

    @on_start
    def start(self, ctx: Context) -> None:
        self._prepare(ctx)

    def _prepare(self, ctx: Context) -> None:
        ctx.publish("/prepare", Prepare(self.state.attempt))
        ctx.after(self.params.vote_timeout_ms, self.on_vote_timeout, self.state.attempt)

    @subscribe("/vote")
    def on_vote(self, ctx: Context, vote: Vote) -> None:
        s = self.state
        if s.phase != "voting":
            return
        if not vote.yes:
            self._decide(ctx, False)
        elif vote.participant not in s.yes:
            s.yes = tuple(sorted((*s.yes, vote.participant)))
            if len(s.yes) == len(self.params.participants):
                self._decide(ctx, True)

    @handler(priority=1)
    def on_vote_timeout(self, ctx: Context, attempt: int) -> None:
        s = self.state
        if s.phase != "voting" or attempt != s.attempt:
            return
        if s.attempt < self.params.retries:
            s.attempt += 1
            self._prepare(ctx)
        else:
            self._decide(ctx, False)

    def _decide(self, ctx: Context, commit: bool) -> None:
        s = self.state
        s.phase, s.commit = "deciding", commit
        ctx.publish("/decision", Decision(commit))
        ctx.after(self.params.ack_timeout_ms, self.on_ack_timeout, s.resent)

    @subscribe("/ack")
    def on_ack(self, ctx: Context, ack: Ack) -> None:
        s = self.state
        if s.phase == "deciding" and ack.participant not in s.acked:
            s.acked = tuple(sorted((*s.acked, ack.participant)))
            if len(s.acked) == len(self.params.participants):
                s.phase = "done"

    @handler(priority=1)
    def on_ack_timeout(self, ctx: Context, resent: int) -> None:
        s = self.state
        if s.phase != "deciding" or resent != s.resent or s.resent >= self.params.retries:
            return
        s.resent += 1
        ctx.publish("/decision", Decision(s.commit))
        ctx.after(self.params.ack_timeout_ms, self.on_ack_timeout, s.resent)


@dataclass(frozen=True)
class ParticipantParams:
    """How a participant votes, and its patience for the decision."""

    vote: bool = True
    decision_timeout_ms: int = 5
    retries: int = 1


@dataclass
class ParticipantState:
    voted: bool = False
    outcome: str = "unknown"  # unknown, commit, abort
    resent: int = 0


class Participant(Node):
    """Votes when asked, repeats its vote while undecided, acknowledges every decision."""

    Params = ParticipantParams

    def initial_state(self) -> ParticipantState:
        return ParticipantState()

    @subscribe("/prepare")
    def on_prepare(self, ctx: Context, prepare: Prepare) -> None:
        if self.state.outcome != "unknown":
            return
        first = not self.state.voted
        self.state.voted = True
        ctx.publish("/vote", Vote(self.name, self.params.vote))
        if first:
            ctx.after(self.params.decision_timeout_ms, self.on_wait_timeout)

    @handler(priority=1)
    def on_wait_timeout(self, ctx: Context) -> None:
        s = self.state
        if s.outcome != "unknown" or s.resent >= self.params.retries:
            return
        s.resent += 1
        ctx.publish("/vote", Vote(self.name, self.params.vote))
        ctx.after(self.params.decision_timeout_ms, self.on_wait_timeout)

    @subscribe("/decision")
    def on_decision(self, ctx: Context, decision: Decision) -> None:
        self.state.outcome = "commit" if decision.commit else "abort"
        ctx.publish("/ack", Ack(self.name))
