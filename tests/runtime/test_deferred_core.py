"""A live node core's deferred replies: a request whose handler called `ctx.defer_reply()`
keeps its responder in the core (never in node state) until `ctx.reply` answers it from a
later handler."""

from __future__ import annotations

from typing import Any

import pytest

from tests.checker.deferred_nodes import Answer, Ask, Relay
from twinfleet import Context, ContractError, Node, ReplyToken, handler, service
from twinfleet.runtime.contract.dispatch import invoke
from twinfleet.runtime.contract.messages import decode, decode_request, encode, encode_request
from twinfleet.runtime.core.node_core import NodeCore
from twinfleet.runtime.core.outbox import CallOutput, LogOutput, Output, ReplyOutput


def drain(core: NodeCore, now: int) -> list[Output]:
    out: list[Output] = []
    while (outputs := core.run_next(now)) is not None:
        out.extend(outputs)
    return out


def relay() -> tuple[Relay, NodeCore]:
    node = Relay("relay")
    core = NodeCore(node, seed=1)
    core.start(0)
    drain(core, 0)
    return node, core


def ask(core: NodeCore, who: str, responder: Any, now: int) -> CallOutput:
    """`who` asks the relay; the relay's call to the backend."""
    request = encode_request(Ask(who), stamp_ms=0, sender=who, reply_to="done")
    assert core.receive_request("relay", request, responder, now) == ()
    (query,) = drain(core, now)  # deferred: no reply yet, only the backend call
    assert isinstance(query, CallOutput) and query.service == "/backend"
    return query


def answer(core: NodeCore, query: CallOutput, who: str, now: int) -> list[Output]:
    core.receive_reply(query.call, encode(Answer(who, "from backend"), sender="backend"),
                       None, "", now)
    return drain(core, now)


def test_a_deferred_request_is_answered_by_a_later_handler_through_its_responder():
    node, core = relay()
    query = ask(core, "a", "to a", 1)
    assert node.state.waiting == [(ReplyToken("/relay", "a", "done", Ask("a")), "a")]
    (reply,) = answer(core, query, "a", 2)
    assert isinstance(reply, ReplyOutput) and reply.responder == "to a"
    assert reply.payload is not None and decode(reply.payload).msg == Answer("a", "from backend")
    assert node.state.waiting == []


def test_each_deferred_request_gets_its_own_reply_in_any_order():
    _, core = relay()
    first, second = ask(core, "a", "to a", 1), ask(core, "b", "to b", 1)
    (to_b,) = answer(core, second, "b", 2)
    (to_a,) = answer(core, first, "a", 3)
    assert (to_a.responder, to_b.responder) == ("to a", "to b")  # type: ignore[union-attr]
    assert decode(to_b.payload).msg.to == "b"  # type: ignore[union-attr,arg-type]


class Twice(Node):
    """Defers, and replies at once and once more to the same token."""

    @service("/twice")
    def serve(self, ctx: Context, req: Ask) -> None:
        token = ctx.defer_reply()
        ctx.reply(token, Answer(req.who, "one"))
        ctx.reply(token, Answer(req.who, "two"))


def test_a_second_reply_to_one_token_is_dropped_with_a_line():
    core = NodeCore(Twice("t"), seed=1)
    core.start(0)
    core.receive_request("serve", encode_request(Ask("a"), stamp_ms=0, sender="a", reply_to="done"), "to a", 0)
    reply, line = drain(core, 0)
    assert isinstance(reply, ReplyOutput) and decode(reply.payload).msg.text == "one"  # type: ignore[arg-type]
    assert isinstance(line, LogOutput) and line.err and "answered already" in line.text


class Undecided(Node):
    """Defers, then still returns a reply, or raises after deferring."""

    @service("/undecided")
    def serve(self, ctx: Context, req: Ask) -> Answer:
        ctx.defer_reply()
        if req.who == "raise":
            raise ValueError("changed its mind")
        return Answer(req.who, "now")

    @handler()
    def later(self, ctx: Context) -> None:
        ctx.defer_reply()


def test_a_handler_that_deferred_and_failed_answers_its_caller_at_once():
    core = NodeCore(Undecided("u"), seed=1)
    core.start(0)
    core.receive_request("serve", encode(Ask("raise"), sender="a"), "to a", 0)
    out = drain(core, 0)
    assert out[-1] == ReplyOutput("to a", None, "server error: ValueError: changed its mind")


def test_a_reply_returned_after_defer_reply_is_a_contract_error():
    node = Undecided("u")
    ctx = Context(node, 0)
    ctx.serving = ReplyToken("/undecided", "a", "done", Ask("a"))
    reply, error = invoke(node, "serve", ctx, (Ask("a"),), expects_reply=True)
    assert reply is None and error is not None and error.contract
    assert "after defer_reply()" in error.message and ctx.effects == []


def test_defer_reply_outside_a_service_handler_and_a_bad_reply_are_refused():
    node = Undecided("u")
    with pytest.raises(ContractError, match="outside a @service handler"):
        Context(node, 0).defer_reply()
    ctx = Context(node, 0)
    with pytest.raises(ContractError, match="needs the token"):
        ctx.reply(("/undecided", "a"), Answer())  # type: ignore[arg-type]
    with pytest.raises(ContractError, match="needs a message response"):
        ctx.reply(ReplyToken("/undecided", "a", "done", Ask()), {"text": "no"})


def test_a_request_names_its_callers_reply_handler():
    msg, _, _, sender, reply_to = decode_request(encode_request(Ask("a"), stamp_ms=0, sender="a", reply_to="done"))
    assert (msg, sender, reply_to) == (Ask("a"), "a", "done")
    assert decode_request(encode(Ask("a")))[4] == ""
    node = Relay("relay")
    core = NodeCore(node, seed=1)
    core.start(0)
    drain(core, 0)
    core.receive_request("relay", encode_request(Ask("a"), stamp_ms=0, sender="a", reply_to="done"), "r", 0)
    (query,) = drain(core, 0)
    assert isinstance(query, CallOutput) and decode_request(query.payload)[4] == "on_backend"
