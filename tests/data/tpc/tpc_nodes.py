"""A two-phase commit with vote and decision timeouts: a protocol whose outcome hinges on
which of a few deliveries, or of a delivery and a timer, comes first.

The coordinator publishes `/prepare`, collects a yes `/vote` from every participant and
publishes a commit `/decision`; if the votes are not all in `vote_timeout_ms` after a
prepare, it prepares again (`retries` times), then decides abort. A participant that voted
waits `decision_timeout_ms` for the decision and then aborts on its own: the protocol's
flaw, so `atomic` (nobody commits while somebody aborts) is violated whenever the decision
reaches one participant after its timeout and another before. With timeouts of a few ms
and latencies of a few ms, how often that happens is a question of timing.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from twinfleet import Context, Node, handler, message, on_start, subscribe

UNDECIDED, COMMIT, ABORT = 0, 1, 2


@message("twinfleet_tpc/Prepare")
class Prepare:
    """A request to vote in round `round`."""

    round: int = 0


@message("twinfleet_tpc/Vote")
class Vote:
    """A participant's vote in a round."""

    voter: str = ""
    round: int = 0
    yes: bool = True


@message("twinfleet_tpc/Decision")
class Decision:
    """The coordinator's decision."""

    commit: bool = False


@dataclass(frozen=True)
class CoordinatorParams:
    """Parameters of Coordinator."""

    participants: int = 3
    vote_timeout_ms: int = 5
    retries: int = 1


@dataclass
class CoordinatorState:
    """State of Coordinator."""

    round: int = 0
    votes: list[str] = field(default_factory=list)
    decided: int = UNDECIDED


class Coordinator(Node):
    """Prepares, collects the votes, decides (module docstring)."""

    Params = CoordinatorParams

    def initial_state(self) -> CoordinatorState:
        return CoordinatorState()

    @on_start
    def start(self, ctx: Context) -> None:
        self._prepare(ctx)

    def _prepare(self, ctx: Context) -> None:
        self.state.round += 1
        self.state.votes = []
        ctx.publish("/prepare", Prepare(self.state.round))
        ctx.after(self.params.vote_timeout_ms, self.vote_timeout, self.state.round)

    @subscribe("/vote")
    def on_vote(self, ctx: Context, msg: Vote) -> None:
        state = self.state
        if state.decided or msg.round != state.round or msg.voter in state.votes:
            return
        state.votes = sorted([*state.votes, msg.voter])
        if len(state.votes) == self.params.participants:
            state.decided = COMMIT
            ctx.publish("/decision", Decision(True))

    @handler()
    def vote_timeout(self, ctx: Context, round_: int) -> None:
        state = self.state
        if state.decided or round_ != state.round:
            return
        if state.round <= self.params.retries:
            self._prepare(ctx)
        else:
            state.decided = ABORT
            ctx.publish("/decision", Decision(False))


@dataclass(frozen=True)
class ParticipantParams:
    """Parameters of Participant."""

    decision_timeout_ms: int = 8


@dataclass
class ParticipantState:
    """State of Participant."""

    waiting: int = 0  # the round of the last vote sent
    outcome: int = UNDECIDED


class Participant(Node):
    """Votes yes on every prepare and waits for the decision, then aborts on its own."""

    Params = ParticipantParams

    def initial_state(self) -> ParticipantState:
        return ParticipantState()

    @subscribe("/prepare")
    def on_prepare(self, ctx: Context, msg: Prepare) -> None:
        if self.state.outcome:
            return
        self.state.waiting = msg.round
        ctx.publish("/vote", Vote(self.name, msg.round, True))
        ctx.after(self.params.decision_timeout_ms, self.decision_timeout, msg.round)

    @handler()
    def decision_timeout(self, ctx: Context, round_: int) -> None:
        if not self.state.outcome and round_ == self.state.waiting:
            self.state.outcome = ABORT

    @subscribe("/decision")
    def on_decision(self, ctx: Context, msg: Decision) -> None:
        if not self.state.outcome:
            self.state.outcome = COMMIT if msg.commit else ABORT
