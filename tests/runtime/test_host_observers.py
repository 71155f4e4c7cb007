"""The event log and the replay gate attached to a NodeHost (LoopbackTransport, no Zenoh)."""

from __future__ import annotations

import asyncio
import io
import json
from pathlib import Path
from typing import Any

import msgpack

from tests.runtime.hosts import (
    FLEET,
    Asker,
    AskerParams,
    Doubler,
    Harness,
    Log,
    Num,
    run,
    settle,
)
from twinfleet import CallError, CallFailure, Context, Node, every, handler, on_start, subscribe
from twinfleet.runtime.contract.kinds import EventKind
from twinfleet.runtime.contract.messages import encode
from twinfleet.runtime.contract.node import QOS_DEFAULT
from twinfleet.runtime.core.eventlog import EVENTS_FORMAT, EventLog, payload_digest
from twinfleet.runtime.host.clock import ManualClock
from twinfleet.runtime.host.keys import KeyKind, node_key, topic_key
from twinfleet.runtime.host.node_host import NodeHost
from twinfleet.runtime.host.replay_gate import LogicalClock
from twinfleet.runtime.host.replay_wire import STATUS, GateStatus, Grant, GrantAnswer, Held
from twinfleet.runtime.host.transport import LoopbackBus, LoopbackTransport


class Ticker(Node):
    """A start, a ctx.after, an @every, a subscription."""

    def initial_state(self) -> Log:
        return Log()

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.after(30, self.later)

    @handler()
    def later(self, ctx: Context) -> None:
        self.state.seen.append("later")

    @every(100)
    def tick(self, ctx: Context) -> None:
        self.state.seen.append(ctx.now())

    @subscribe("/nums")
    def on_num(self, ctx: Context, msg: Num) -> None:
        self.state.seen.append(msg.value)


def _events(path: Path) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    header, *events = (json.loads(line) for line in path.read_text().splitlines())
    return header, events


def test_the_event_log_names_each_kind_of_event(tmp_path: Path) -> None:
    async def body() -> None:
        h = Harness()
        logs = {name: EventLog(str(tmp_path / f"{name}.jsonl"), node=name)
                for name in ("ticker", "doubler", "asker", "lonely")}
        await h.start(Ticker("ticker"), events=logs["ticker"])
        await h.start(Doubler("doubler"), events=logs["doubler"])
        await h.start(Asker("asker"), events=logs["asker"])
        await h.start(Asker("lonely", AskerParams(service="/missing")), events=logs["lonely"])
        raw = await h.raw()
        raw.put(topic_key(FLEET, "/nums"), encode(Num(5), seq=1, sender="x"), QOS_DEFAULT)
        await settle(*h.hosts)
        await h.advance(100)
        await h.stop()
        for log in logs.values():
            log.close()

    run(body())
    header, ticker = _events(tmp_path / "ticker.jsonl")
    assert (header["format"], header["kind"]) == (EVENTS_FORMAT, "header") == (
        "twinfleet-events/2", "header")
    assert [(e["kind"], e["handler"], e["due"]) for e in ticker] == [
        ("start", "start", 0), ("delivery", "on_num", None), ("timer", "later", 30),
        ("periodic", "tick", 100)]
    assert [e["i"] for e in ticker] == [0, 1, 2, 3]
    (request,) = _events(tmp_path / "doubler.jsonl")[1]
    assert (request["kind"], request["sender"], request["topic"]) == ("request", "asker", "/double")
    reply = _events(tmp_path / "asker.jsonl")[1][1]
    assert (reply["kind"], reply["sender"], reply["args"]) == (
        "reply", "doubler", payload_digest((Num(42),)))
    timeout = _events(tmp_path / "lonely.jsonl")[1][1]
    assert (timeout["kind"], timeout["sender"], timeout["topic"], timeout["args"]) == (
        "timeout", "lonely", "/missing", payload_digest((CallError("/missing", CallFailure.NO_SERVER, "no server"),)))


async def _ask(transport: LoopbackTransport, node: str, payload: bytes) -> bytes:
    done: asyncio.Future[tuple[bytes | None, str]] = asyncio.get_running_loop().create_future()
    transport.query(node_key(FLEET, KeyKind.REPLAY, node), payload, 5_000.0,
                    lambda reply, _failure, reason: done.done() or done.set_result((reply, reason)))
    reply, reason = await done
    assert reply is not None, reason
    return reply


async def _grant(transport: LoopbackTransport, node: str, grant: Grant) -> GrantAnswer:
    return GrantAnswer.decode(await _ask(transport, node, grant.encode()))


def test_a_gated_host_runs_only_what_is_granted_and_waits_for_what_is_in_flight() -> None:
    async def body() -> tuple[list[Any], list[GrantAnswer], GateStatus]:
        bus = LoopbackBus()
        transport, coordinator = LoopbackTransport(bus), LoopbackTransport(bus)
        await transport.open()
        await coordinator.open()
        node = Ticker("ticker")
        host = NodeHost(node, transport, LogicalClock(), seed=1, fleet=FLEET, gated=True,
                        out=io.StringIO())
        task = asyncio.create_task(host.run())
        for _ in range(50):
            await asyncio.sleep(0)
        status = GateStatus.decode(await _ask(coordinator, "ticker", STATUS))
        answers = [await _grant(coordinator, "ticker", Grant(EventKind.START, "start", "ticker",
                                                             payload_digest(()), 0))]
        # a grant for a message still in flight waits for it
        waiting = asyncio.create_task(_grant(coordinator, "ticker", Grant(
            EventKind.DELIVERY, "on_num", "x", payload_digest((Num(5),)), 7)))
        for _ in range(50):
            await asyncio.sleep(0)
        assert not waiting.done() and node.state.seen == []
        coordinator.put(topic_key(FLEET, "/nums"), encode(Num(5), seq=1, sender="x"), QOS_DEFAULT)
        answers.append(await waiting)
        answers.append(await _grant(coordinator, "ticker", Grant(
            EventKind.PERIODIC, "tick", "ticker", payload_digest(()), 100)))
        host.stop()
        await task
        return node.state.seen, answers, status

    seen, answers, status = run(body())
    assert seen == [5, 100]  # the after timer was never granted, so it never ran
    assert [a.error for a in answers] == [None, None, None]
    assert [h.kind for h in status.ready] == ["start", "periodic"] and status.waiting is None


def test_a_malformed_grant_is_a_one_line_server_error() -> None:
    async def body() -> tuple[bytes | None, CallFailure | None, str]:
        bus = LoopbackBus()
        transport, coordinator = LoopbackTransport(bus), LoopbackTransport(bus)
        await transport.open()
        await coordinator.open()
        host = NodeHost(Ticker("ticker"), transport, LogicalClock(), seed=1, fleet=FLEET,
                        gated=True, out=io.StringIO())
        task = asyncio.create_task(host.run())
        for _ in range(50):
            await asyncio.sleep(0)
        done: asyncio.Future[tuple[bytes | None, CallFailure | None, str]] = \
            asyncio.get_running_loop().create_future()
        coordinator.query(node_key(FLEET, KeyKind.REPLAY, "ticker"),
                          msgpack.packb({"kind": "start", "handler": "start"}), 5_000.0,
                          lambda *answer: done.done() or done.set_result(answer))
        answer = await done
        host.stop()
        await task
        return answer

    assert run(body()) == (None, CallFailure.SERVER_ERROR,
                           "server error: bad grant (grant: missing sender, args, t)")


def test_the_wire_values_round_trip() -> None:
    grant = Grant(EventKind.TIMER, "later", "ticker", payload_digest((3,)), 30, (1, 0), 4)
    answer = GrantAnswer("ab" * 12, (1,), (2,), (("/nums", "test/Num"),), None)
    status = GateStatus((Held("timer", "later", "ticker", grant.args, "(3,)"),), 2, grant)
    assert Grant.decode(grant.encode()) == grant
    assert GrantAnswer.decode(answer.encode()) == answer
    assert GateStatus.decode(status.encode()) == status


def test_a_gated_host_needs_a_logical_clock() -> None:
    try:
        NodeHost(Ticker("t"), LoopbackTransport(), ManualClock(), seed=1, fleet=FLEET, gated=True)
    except ValueError as exc:
        assert "LogicalClock" in str(exc)
    else:
        raise AssertionError("a gated host accepted a ManualClock")
