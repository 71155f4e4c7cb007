"""A node core's outputs, and the `Outbox` that turns what a handler did into them.

Outputs are values the driver performs in order, each named after the effect it
carries out (`contract.context`: `Publish`, `Call`, `Log`), plus the reply and the stop (`runtime.host.node_host.NodeHost.perform`
live): `PublishOutput` (an encoded envelope on a topic), `CallOutput` (a service call whose
answer goes back to `NodeCore.receive_reply`), `ReplyOutput` (the reply to the
request that ran, or to a deferred one), `LogOutput` (a log line), `StopOutput`
(``stop_on_error`` after a failure). A request whose handler deferred its reply
(`contract.context.Defer`) leaves its responder here, kept by its token (never in node
state: a responder is the transport's query), until a `Reply` effect answers it
(`park`); a transport that closes answers the queries it still holds. The `Outbox` numbers each topic's envelopes (a per-publisher
sequence number that receivers check for gaps; a message that cannot be
encoded takes no number), arms the due entries of `ctx.after` and `ctx.call`,
and reports failures: a line, a `Violation` published on /violations as if
the handler had published it, a "server error: ..." answer to a caller.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Final, NamedTuple, final

from twinfleet.runtime.contract.context import (
    After,
    Call,
    Effect,
    Fail,
    Log,
    Publish,
    Reply,
    ReplyToken,
)
from twinfleet.runtime.contract.dispatch import HandlerError
from twinfleet.runtime.contract.kinds import EventKind
from twinfleet.runtime.contract.messages import Violation, encode, encode_request
from twinfleet.runtime.core.due import DueEntries
from twinfleet.runtime.core.events import Event

VIOLATIONS_TOPIC: Final = "/violations"


class PublishOutput(NamedTuple):
    """Publish `payload` (an encoded envelope) on the absolute `topic`.

    A NamedTuple, not a frozen dataclass like the other outputs: one is built per
    published message, and a tuple is built in half the time.
    """

    topic: str
    payload: bytes


@dataclass(frozen=True, slots=True)
class CallOutput:
    """Ask the server of `service`; hand its answer to `NodeCore.receive_reply(call, ...)`."""

    call: int
    service: str
    payload: bytes
    timeout_ms: int  # fleet ms; the core's TIMEOUT entry fires then whatever the transport does


@dataclass(frozen=True, slots=True)
class ReplyOutput:
    """Reply to the request that ran through `responder`: a payload, or None and a reason."""

    responder: Any
    payload: bytes | None
    reason: str


@dataclass(frozen=True, slots=True)
class LogOutput:
    """A log line (`err`: a warning or an error)."""

    text: str
    err: bool = False


@dataclass(frozen=True, slots=True)
class StopOutput:
    """Stop the node: a handler failed under ``stop_on_error``."""

    reason: str


Output = PublishOutput | CallOutput | ReplyOutput | LogOutput | StopOutput

# `PublishOutput((topic, payload))`, without the Python-level `__new__` a NamedTuple has: the hot path.
_put: Final = functools.partial(tuple.__new__, PublishOutput)



def _violation(node: str, handler: str, reason: str) -> tuple[Publish]:
    """What a failure publishes, as if the handler had: a `Violation` on /violations."""
    return (Publish(VIOLATIONS_TOPIC, Violation(node, handler, reason)),)


@final
class Outbox:
    """Turns one node's handler runs into outputs (module docstring).

    Args:
        name: the node's name, the sender of everything it sends.
        due: the node's due entries: `ctx.after` arms a timer there, `ctx.call` a timeout.
        counters: the core's counters; ``published``, ``failures`` and ``errors`` count here.
        stop_on_error: end a failure's outputs with a `StopOutput`.
    """

    def __init__(self, name: str, due: DueEntries, counters: dict[str, int], *,
                 stop_on_error: bool = False) -> None:
        self.name, self.due, self.stop_on_error = name, due, stop_on_error
        self._n = counters
        self._seq: dict[str, int] = {}  # topic -> last sequence number sent
        # deferred requests, oldest first (a list: a token holds a message, maybe unhashable)
        self._parked: list[tuple[ReplyToken, Any]] = []

    def park(self, token: ReplyToken, responder: Any) -> Any:
        """Keep the responder of a request whose handler deferred its reply; None, the
        responder the request's own step then has (nothing answers it now)."""
        self._parked.append((token, responder))
        return None

    def unpark(self, token: ReplyToken) -> Any:
        """The responder of the oldest deferred request `token` names, taken out (None:
        none waits, it was answered already)."""
        for k, (parked, responder) in enumerate(self._parked):
            if parked == token:
                del self._parked[k]
                return responder
        return None

    def translate(self, effects: Sequence[Effect], now: int, method: str,
                  out: list[Output]) -> HandlerError | None:
        """Effects → outputs, in order; an effect that fails (unencodable) ends the handler's."""
        name, seqs, n = self.name, self._seq, self._n
        try:
            for effect in effects:
                if type(effect) is Publish:  # by far the most frequent: inline, no matching
                    topic = effect.topic
                    seq = seqs.get(topic, 0) + 1
                    out.append(_put((topic, encode(effect.msg, stamp_ms=now, seq=seq, sender=name))))
                    seqs[topic] = seq  # after the encode: an unencodable message takes no number
                    n["published"] += 1
                    continue
                match effect:
                    case Call():
                        out.append(self._query(effect, now))
                    case Reply(token=token, msg=msg):
                        out.append(self._answer(token, msg, now))
                    case After(delay_ms=delay, handler=handler, args=args):
                        self.due.arm(Event(EventKind.TIMER, handler, args, name, due=now + delay))
                        if 0 < delay < (n["period"] or delay + 1):  # the stall threshold's base
                            n["period"] = delay
                    case Fail(reason=reason):
                        n["failures"] += 1
                        out.append(LogOutput(f"t={now} FAIL {reason}", err=True))
                        self.translate(_violation(name, "", reason), now, method, out)
                    case Log(event=event, fields=fields):
                        text = " ".join(f"{k}={v!r}" for k, v in fields)
                        out.append(LogOutput(f"t={now} {event}" + (f" {text}" if text else "")))
        except Exception as exc:  # e.g. a message msgpack cannot encode (an int ≥ 2**64)
            return HandlerError(name, method, f"effect failed: {exc!r}")
        return None

    def _query(self, call: Call, now: int) -> CallOutput:
        cid = self.due.open_call(call, now)
        payload = encode_request(call.request, stamp_ms=now, sender=self.name,
                                 reply_to=call.reply_to)
        return CallOutput(cid, call.service, payload, call.timeout_ms)

    def _answer(self, token: ReplyToken, msg: Any, now: int) -> Output:
        payload = encode(msg, stamp_ms=now, sender=self.name)  # before unpark: may raise
        responder = self.unpark(token)
        if responder is None:
            return LogOutput(f"t={now} reply to {token.service} for {token.caller} dropped: "
                             "no deferred request of that token waits (answered already?)",
                             err=True)
        return ReplyOutput(responder, payload, "")

    def report(self, error: HandlerError, args: tuple[Any, ...], now: int,
               out: list[Output]) -> None:
        """A failed handler: count it, log it, publish a `Violation` (and `StopOutput` if asked)."""
        self._n["errors"] += 1
        detail = ", ".join(repr(a)[:120] for a in args)
        out.append(LogOutput(f"error in handler {error} (args: {detail})", err=True))
        if error.traceback:
            out.append(LogOutput(error.traceback.rstrip(), err=True))
        self.translate(_violation(error.node, error.handler, error.message), now, error.handler,
                        out)
        if self.stop_on_error:
            out.append(LogOutput("stopping: live.stop_on_error is set", err=True))
            out.append(StopOutput(f"{error}"))

    def finish(self, method: str, args: tuple[Any, ...], reply: Any, error: HandlerError | None,
               responder: Any, now: int, out: list[Output]) -> HandlerError | None:
        """After the effects: a service's reply or its error, and the report of a failure."""
        payload = None
        if responder is not None and error is None:
            try:
                payload = encode(reply, stamp_ms=now, sender=self.name)
            except Exception as exc:
                error = HandlerError(self.name, method, f"unencodable reply: {exc!r}")
        if error is not None:
            self.report(error, args, now, out)
        if responder is not None:
            out.append(ReplyOutput(responder, payload, "") if error is None
                       else ReplyOutput(responder, None, f"server error: {error.message}"))
        return error
