"""NodeCore alone — no loop, no transport, no clock: arrivals in, outputs out, time given."""

from __future__ import annotations

import ast
from pathlib import Path
from typing import Any

import pytest

from tests.runtime.hosts import Doubler, Log, Num, Recorder, Shallow
from twinfleet import (
    CallError,
    CallFailure,
    Context,
    Node,
    handler,
    on_start,
    subscribe,
)
from twinfleet.runtime.contract.kinds import EventKind
from twinfleet.runtime.contract.messages import DecodeError, NodeAlive, Violation, decode, encode
from twinfleet.runtime.contract.names import BRIDGE_SENDER, OPERATOR_SENDER
from twinfleet.runtime.core.choosers import RecordingChooser
from twinfleet.runtime.core.events import Event
from twinfleet.runtime.core.node_core import MAX_GAP, Handled, NodeCore
from twinfleet.runtime.core.outbox import (
    CallOutput,
    LogOutput,
    Output,
    PublishOutput,
    ReplyOutput,
    StopOutput,
)
from twinfleet.runtime.core.statistics import Outside

ROOT = Path(__file__).resolve().parents[2]


class Faulty(Node):
    """Fails in every way a handler can: raises, ctx.fail, an unencodable publish."""

    def initial_state(self) -> Log:
        return Log()

    @subscribe("/high")
    def on_high(self, ctx: Context, msg: Num) -> None:
        self.state.seen.append((ctx.now(), f"high {msg.value}"))
        if msg.value < 0:
            raise ValueError("negative")
        if msg.value == 13:
            ctx.fail("unlucky")
        if msg.value == 99:
            ctx.publish("/out", Num(2**64))  # msgpack cannot encode it
        if msg.value == 7:
            ctx.publish("/out", Num(7))


class Caller(Node):
    def initial_state(self) -> Log:
        return Log()

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.call("/double", Num(21), self.on_reply, timeout_ms=200)

    @handler(priority=4)
    def on_reply(self, ctx: Context, reply: Num | CallError) -> None:
        self.state.seen.append((ctx.now(), reply))


class Watcher(Node):
    def initial_state(self) -> Log:
        return Log()

    @subscribe("/_liveliness")
    def on_alive(self, ctx: Context, msg: NodeAlive) -> None:
        self.state.seen.append(msg)


class Records:
    """An observer that keeps every record."""

    def __init__(self) -> None:
        self.records: list[Handled] = []

    def handled(self, record: Handled) -> None:
        self.records.append(record)


def sample(value: int, seq: int = 1, sender: str = "a", stamp: int = 0) -> bytes:
    return encode(Num(value), stamp_ms=stamp, seq=seq, sender=sender)


def drain(core: NodeCore, now: int) -> list[Output]:
    """Run everything ready at `now`; the outputs of all handlers, in order."""
    out: list[Output] = []
    while (outputs := core.run_next(now)) is not None:
        out.extend(outputs)
    return out


def started(node: Node, now: int = 0, **kw: Any) -> NodeCore:
    core = NodeCore(node, seed=1, **kw)
    core.start(now)
    return core


# ---------------------------------------------------------------- ordering


def test_one_millisecond_runs_by_priority_then_arrival_and_earlier_arrivals_first():
    node = Recorder("busy")
    core = started(node)
    drain(core, 0)
    low, high = core.receiver("on_low"), core.receiver("on_high")
    low(sample(0, seq=1), 5)  # an earlier millisecond beats any priority
    for value, receive, arrival in ((1, low, 10), (2, high, 10), (3, low, 10), (4, high, 10)):
        receive(sample(value, seq=value + 1), arrival)
    drain(core, 11)
    assert [e for _, e in node.state.seen[1:]] == ["low 0", "high 2", "high 4", "low 1", "low 3"]
    assert {t for t, _ in node.state.seen[1:]} == {11}  # deliveries see the time they run


def test_start_runs_before_what_arrived_before_it():
    node = Recorder("busy")
    core = NodeCore(node, seed=1)
    core.receiver("on_high")(sample(1), 0)
    assert core.has_ready()
    core.start(3)
    drain(core, 3)
    assert node.state.seen == [(3, "start"), (3, "high 1")]


def test_after_and_every_are_due_entries_that_run_at_their_due_time():
    node = Recorder("busy")
    core = started(node)
    drain(core, 0)
    assert core.next_due() == 50
    assert core.release_due(49) == 0
    assert core.release_due(50) == 1
    drain(core, 57)  # the loop is late: the handler still sees its due time
    assert core.next_due() == 100
    assert core.release_due(100) == 2
    drain(core, 100)
    assert core.next_due() == 200  # each tick re-armed one period later: no drift
    assert node.state.seen == [(0, "start"), (50, "later x"), (100, "tick p1"), (100, "tick p2")]
    assert core.statistics().timers_pending == 2


def test_a_late_tick_skips_the_periods_it_missed():
    node = Recorder("busy")
    core = started(node)
    drain(core, 0)
    assert core.release_due(1000) == 3  # the after at 50, the two ticks at 100, once each
    assert core.next_due() == 1100  # the first tick after now, not 200
    drain(core, 1000)
    assert [t for t, e in node.state.seen if e.startswith("tick")] == [100, 100]


# ---------------------------------------------------------------- KEEP_LAST, gaps, decoding


def test_keep_last_keeps_the_newest_waiting_messages_and_counts_the_others():
    node = Shallow("s")
    core = started(node)
    receive = core.receiver("on_num")
    added = [receive(sample(seq, seq=seq), seq) for seq in range(1, 11)]
    assert added == [True] * 3 + [False] * 7  # three slots; later ones replace the oldest
    drain(core, 20)
    assert node.state.seen == [8, 9, 10]
    stats = core.statistics()
    assert (stats.dropped_keep_last, stats.gaps, stats.received, stats.inbox_depth) == (7, 0, 10, 0)


def test_gaps_are_counted_per_sender_and_best_effort_losses_apart():
    core = started(Shallow("s"))
    nums, other = core.receiver("on_num"), core.receiver("on_other")
    for sender, seq in (("a", 1), ("b", 1), ("a", 2), ("a", 5), ("b", 2), ("a", 6)):
        nums(sample(2, seq=seq, sender=sender), 0)
        drain(core, 0)
    for seq in (1, 2, 5, 6, 9):
        other(sample(2, seq=seq), 0)
        drain(core, 0)
    stats = core.statistics()
    assert (stats.gaps, stats.dropped_best_effort) == (2, 4)


def test_a_leap_beyond_max_gap_is_one_sequence_jump_not_lost_messages():
    core = started(Shallow("s"))
    receive = core.receiver("on_num")
    for seq in (1, 2, 4, 2 + MAX_GAP * 1000, 3 + MAX_GAP * 1000, 6 + MAX_GAP * 1000):
        receive(sample(2, seq=seq), 0)
        drain(core, 0)
    stats = core.statistics()
    assert (stats.gaps, stats.sequence_jumps) == (1 + 2, 1)


def test_an_undecodable_sample_is_counted_and_raised():
    core = started(Shallow("s"))
    with pytest.raises(DecodeError):
        core.receiver("on_num")(b"\xc1 not msgpack", 0)
    stats = core.statistics()
    assert (stats.received, stats.dropped_undecodable, stats.inbox_depth) == (1, 1, 0)


def test_liveliness_reaches_a_liveliness_subscriber_only():
    node = Watcher("w")
    core = started(node)
    assert core.receive_liveliness("r1", True, 4)
    drain(core, 4)
    assert node.state.seen == [NodeAlive("r1", True)]
    assert not started(Doubler("d")).receive_liveliness("r1", True, 4)


# ---------------------------------------------------------------- services and calls


def test_a_request_runs_its_service_and_answers_through_its_responder():
    core = started(Doubler("d"))
    responder = object()
    assert core.receive_request("double", encode(Num(21), sender="c"), responder, 3) == ()
    (answer,) = drain(core, 3)
    assert isinstance(answer, ReplyOutput) and answer.responder is responder
    assert answer.payload is not None and decode(answer.payload).msg == Num(42)


def test_a_service_that_raises_answers_a_server_error_and_reports_it():
    core = started(Doubler("d"))
    out = [] if core.receive_request("double", encode(Num(-1)), "r", 0) else drain(core, 0)
    lines = [o for o in out if isinstance(o, LogOutput)]
    (put,) = [o for o in out if isinstance(o, PublishOutput)]
    assert out[-1] == ReplyOutput("r", None, "server error: ValueError: negative")
    assert lines[0].err and lines[0].text.startswith("error in handler d.double: ValueError")
    assert (put.topic, decode(put.payload).msg) == (
        "/violations", Violation("d", "double", "ValueError: negative"))
    assert core.statistics().handler_errors == 1


def test_an_undecodable_request_is_answered_at_once():
    core = started(Doubler("d"))
    line, answer = core.receive_request("double", b"junk", "r", 0)
    assert isinstance(line, LogOutput) and line.err
    assert answer.reason.startswith("server error: undecodable request")
    assert not core.has_ready()


def _call(core: NodeCore) -> CallOutput:
    (query,) = drain(core, 10)
    assert isinstance(query, CallOutput) and query.service == "/double" and query.timeout_ms == 200
    assert decode(query.payload).msg == Num(21)
    return query


def test_a_reply_runs_the_reply_handler_and_voids_the_timeout():
    node = Caller("c")
    core = started(node, now=10)
    query = _call(core)
    assert core.next_due() == 210
    assert core.receive_reply(query.call, encode(Num(42), stamp_ms=12, sender="d"), None, "", 15)
    drain(core, 15)
    assert node.state.seen == [(15, Num(42))]
    assert core.next_due() is None and core.release_due(10_000) == 0


def test_no_answer_in_time_runs_the_reply_handler_with_a_timeout_at_its_due_time():
    node = Caller("c")
    core = started(node, now=10)
    query = _call(core)
    assert core.release_due(209) == 0
    assert core.release_due(210) == 1
    drain(core, 213)
    assert node.state.seen == [(210, CallError("/double", CallFailure.TIMEOUT, "timeout"))]
    assert not core.receive_reply(query.call, encode(Num(42)), None, "", 300)  # too late: ignored


def test_a_call_error_from_the_transport_is_a_timeout_event():
    node, recorder = Caller("c"), Records()
    core = NodeCore(node, seed=1)
    core.observe(recorder)
    core.start(10)
    query = _call(core)
    assert core.receive_reply(query.call, None, CallFailure.NO_SERVER, "no server", 11)
    drain(core, 11)
    assert node.state.seen == [(11, CallError("/double", CallFailure.NO_SERVER, "no server"))]
    entry = recorder.records[-1].entry
    assert (entry.kind, entry.sender, entry.topic) == (EventKind.TIMEOUT, "c", "/double")


# ---------------------------------------------------------------- failures


def test_a_handler_exception_is_reported_and_the_next_entries_still_run():
    node = Faulty("busy")
    core = started(node)
    receive = core.receiver("on_high")
    receive(sample(-1, seq=1), 1)
    receive(sample(3, seq=2), 1)
    out = drain(core, 1)
    assert [type(o) for o in out] == [LogOutput, LogOutput, PublishOutput]  # error, traceback, violation
    assert decode(out[2].payload).msg == Violation("busy", "on_high", "ValueError: negative")
    assert node.state.seen[-1] == (1, "high 3")
    assert core.statistics().handler_errors == 1


def test_a_handler_that_raises_leaves_the_state_as_before_it_ran():
    node = Faulty("busy")
    core = started(node)
    receive = core.receiver("on_high")
    receive(sample(3, seq=1), 1)
    receive(sample(-1, seq=2), 2)  # appends to the state, then raises
    drain(core, 2)
    assert node.state.seen == [(2, "high 3")]  # the partial change is rolled back
    receive(sample(4, seq=3), 3)
    drain(core, 3)
    assert node.state.seen == [(2, "high 3"), (3, "high 4")]


def test_a_state_that_cannot_be_copied_is_the_handlers_failure_and_rolled_back():
    class Leaky(Node):
        def initial_state(self) -> Log:
            return Log()

        @subscribe("/high")
        def on_high(self, ctx: Context, msg: Num) -> None:
            self.state.seen.append(lambda: msg)  # not a value: the checker refuses it too
            ctx.publish("/out", Num(1))

    node = Leaky("leaky")
    core = started(node)
    core.receiver("on_high")(sample(1), 1)
    out = drain(core, 1)
    assert node.state.seen == []
    assert not any(isinstance(o, PublishOutput) and o.topic.endswith("/out") for o in out)
    assert core.statistics().handler_errors == 1


def test_arrivals_before_a_new_epoch_keep_their_order_and_later_ones_still_arrive():
    node = Faulty("busy")
    core = NodeCore(node, seed=1)
    receive = core.receiver("on_high")
    receive(sample(1, seq=1), 9000)  # stamped on the launcher's clock, before time 0
    core.shift_arrivals(9000 - 2)  # the fleet's epoch came: those arrived at t=-2
    core.start(0)
    receive(sample(2, seq=2), 1)
    drain(core, 3)
    assert node.state.seen == [(3, "high 1"), (3, "high 2")]


def test_stop_on_error_adds_a_stop_output():
    core = started(Faulty("busy"), stop_on_error=True)
    core.receiver("on_high")(sample(-1), 1)
    out = drain(core, 1)
    assert isinstance(out[-1], StopOutput) and "negative" in out[-1].reason


def test_fail_is_counted_logged_and_published():
    core = started(Faulty("busy"))
    core.receiver("on_high")(sample(13), 2)
    line, put = drain(core, 2)
    assert line == LogOutput("t=2 FAIL unlucky", err=True)
    assert decode(put.payload).msg == Violation("busy", "", "unlucky")
    assert core.statistics().failures == 1


def test_an_unencodable_publish_is_a_handler_error_that_takes_no_sequence_number():
    core = started(Faulty("busy"))
    receive = core.receiver("on_high")
    receive(sample(99, seq=1), 2)
    receive(sample(7, seq=2), 2)
    out = drain(core, 2)
    assert out[0].text.startswith("error in handler busy.on_high: effect failed")
    (put,) = [o for o in out if isinstance(o, PublishOutput) and o.topic == "/out"]
    assert decode(put.payload).seq == 1


# ---------------------------------------------------------------- observers and the gate's way in


def test_observers_see_every_run_with_a_named_entry():
    node, recorder = Recorder("busy"), Records()
    core = NodeCore(node, seed=1)
    core.observe(recorder)
    core.start(0)
    core.receiver("on_low")(sample(5, seq=3, sender="r2", stamp=1), 2)
    drain(core, 2)
    core.release_due(100)
    drain(core, 100)
    seen = [(r.entry.kind, r.entry.handler, r.entry.sender, r.entry.due, r.now)
            for r in recorder.records]
    assert seen[0] == (EventKind.START, "start", "busy", 0, 0)  # at its start time
    assert seen[1] == (EventKind.DELIVERY, "on_low", "r2", None, 2)
    assert seen[2:] == [(EventKind.TIMER, "later", "busy", 50, 50),
                        (EventKind.PERIODIC, "fast_tick", "busy", 100, 100),
                        (EventKind.PERIODIC, "slow_tick", "busy", 100, 100)]
    delivery = recorder.records[1].entry
    assert (delivery.topic, delivery.seq, delivery.stamp, delivery.args) == ("/low", 3, 1, (Num(5),))
    assert recorder.records[0].effects[0].handler == "later"  # the effects as recorded


def test_pending_lists_everything_and_run_takes_any_of_it_out_of_turn():
    node = Shallow("s")
    core = NodeCore(node, seed=1, keep_last=False)  # the replay gate's core holds every message
    core.start(0)
    receive = core.receiver("on_num")
    for seq in range(1, 6):
        receive(sample(seq, seq=seq), seq)
    pending = core.pending()
    assert [e.args[0].value for e in pending] == [1, 2, 3, 4, 5]
    chooser = RecordingChooser(None)
    core.run(pending[3], 40, chooser)
    assert node.state.seen == [4]
    drain(core, 50)  # the others keep their order
    assert node.state.seen == [4, 1, 2, 3, 5]
    with pytest.raises(ValueError, match="not pending"):
        core.run(pending[0], 60)


def test_run_takes_timers_before_they_are_due_and_a_taken_tick_re_arms():
    node = Recorder("busy")
    core = NodeCore(node, seed=1)
    core.start(0)
    start, tick1, tick2 = core.pending()
    assert (start.kind, tick1.kind, tick2.kind) == (
        EventKind.START, EventKind.PERIODIC, EventKind.PERIODIC)
    core.run(start, 0)
    later = next(e for e in core.pending() if e.kind is EventKind.TIMER)
    core.run(tick1, 100)
    core.run(later, 120)
    assert node.state.seen == [(0, "start"), (100, "tick p1"), (120, "later x")]
    assert [e.due for e in core.pending() if e.handler == "fast_tick"] == [200]


def test_entries_are_named_and_frozen():
    entry = Event(EventKind.DELIVERY, "on_num", (Num(1),), "a", "/nums", 3, 7)
    with pytest.raises(AttributeError):
        entry.seq = 4  # type: ignore[misc]
    assert entry != Event(EventKind.DELIVERY, "on_num", (Num(1),), "a", "/nums", 3, 7)  # identity


@pytest.mark.parametrize("module", ["node_core", "due", "events", "choosers", "outbox"])
def test_the_core_knows_no_asyncio_and_does_no_io(module):
    tree = ast.parse((ROOT / "twinfleet" / "runtime" / "core" / f"{module}.py").read_text())
    names = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    names |= {n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    banned = {"asyncio", "zenoh", "socket", "threading", "time", "twinfleet.runtime.host.clock",
              "twinfleet.runtime.host.transport", "twinfleet.runtime.host.node_host",
              "twinfleet.runtime.host.zenoh_transport", "twinfleet.runtime.core.eventlog"}
    assert not names & banned
    calls = {n.func.id for n in ast.walk(tree) if isinstance(n, ast.Call)
             and isinstance(n.func, ast.Name)}
    assert not calls & {"open", "print", "input"}


def test_what_came_from_outside_the_fleet_is_counted_per_source_and_name():
    recorder = started(Recorder("busy"))
    drain(recorder, 0)
    recorder.receiver("on_low")(sample(1, sender=OPERATOR_SENDER), 1)
    recorder.receiver("on_low")(sample(2, seq=2, sender="a"), 1)  # a fleet node: not counted
    recorder.receiver("on_high")(sample(3, sender=BRIDGE_SENDER), 1)
    drain(recorder, 1)
    doubler = started(Doubler("d"))
    doubler.receive_request("double", encode(Num(2), sender=OPERATOR_SENDER), "r", 0)
    drain(doubler, 0)
    assert recorder.statistics().outside_input == (
        (Outside.OPERATOR, "/low", 1), (Outside.BRIDGE, "/high", 1))
    assert doubler.statistics().outside_input == ((Outside.OPERATOR, "/double", 1),)
