"""Native nodes whose service replies later (`ctx.defer_reply` / `ctx.reply`): a relay
that asks a backend before it answers, and a relay that answers the wrong caller.

Only the node contract is used: these nodes run live as well (tests/runtime).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from twinfleet import CallError, Context, Node, ReplyToken, handler, message, on_start, service


@message("twinfleet_test/Ask")
class Ask:
    """A question: who asks."""

    who: str = ""


@message("twinfleet_test/Answer")
class Answer:
    """An answer: for whom, and what the backend said."""

    to: str = ""
    text: str = ""


class Backend(Node):
    """Answers at once."""

    @service("/backend")
    def answer(self, ctx: Context, req: Ask) -> Answer:
        return Answer(req.who, "from backend")


@dataclass
class RelayState:
    """The deferred requests, oldest first, each with its question."""

    waiting: list[tuple[ReplyToken, str]] = field(default_factory=list)


class Relay(Node):
    """Asks the backend for each request and answers that request's caller with it."""

    def initial_state(self) -> RelayState:
        return RelayState()

    @service("/relay")
    def relay(self, ctx: Context, req: Ask) -> None:
        self.state.waiting.append((ctx.defer_reply(), req.who))
        ctx.call("/backend", Ask(req.who), self.on_backend)

    @handler()
    def on_backend(self, ctx: Context, answer: Answer | CallError) -> None:
        if isinstance(answer, CallError):
            return
        for k, (token, who) in enumerate(self.state.waiting):
            if who == answer.to:
                del self.state.waiting[k]
                ctx.reply(token, answer)
                return


@dataclass
class SloppyState:
    """Only the last request's token."""

    last: ReplyToken | None = None


class SloppyRelay(Node):
    """Keeps only the last request's token: with two callers, one gets the other's answer
    (and the first never gets one)."""

    def initial_state(self) -> SloppyState:
        return SloppyState()

    @service("/relay")
    def relay(self, ctx: Context, req: Ask) -> None:
        self.state.last = ctx.defer_reply()
        ctx.call("/backend", Ask(req.who), self.on_backend)

    @handler()
    def on_backend(self, ctx: Context, answer: Answer | CallError) -> None:
        if self.state.last is not None and not isinstance(answer, CallError):
            ctx.reply(self.state.last, answer)


@dataclass
class AskerState:
    """What the relay answered (who it was for)."""

    got: str = ""


@dataclass
class SlowState:
    """The one deferred request."""

    token: ReplyToken | None = None


class SlowRelay(Node):
    """Replies 1.5 s after the request: after the caller's 1 s timeout."""

    def initial_state(self) -> SlowState:
        return SlowState()

    @service("/relay")
    def relay(self, ctx: Context, req: Ask) -> None:
        self.state.token = ctx.defer_reply()
        ctx.after(1500, self.late)

    @handler()
    def late(self, ctx: Context) -> None:
        if self.state.token is not None:
            ctx.reply(self.state.token, Answer(self.state.token.caller, "late"))
            self.state.token = None
            ctx.publish("/late", Answer("", "replied"))


class Asker(Node):
    """Asks the relay once, at start, in its own name; says what it got on /answered."""

    def initial_state(self) -> AskerState:
        return AskerState()

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.call("/relay", Ask(self.name), self.done, timeout_ms=1000)

    @handler()
    def done(self, ctx: Context, answer: Answer | CallError) -> None:
        self.state.got = "error" if isinstance(answer, CallError) else answer.to
        ctx.publish("/answered", Answer(self.name, self.state.got))
