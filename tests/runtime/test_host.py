"""NodeHost over LoopbackTransport with a ManualClock: ordering, timers, calls, failures."""

from __future__ import annotations

import asyncio
import hashlib
from typing import Any

from tests.runtime.hosts import (
    FLEET,
    Asker,
    AskerParams,
    Doubler,
    Harness,
    Log,
    Num,
    Recorder,
    Shallow,
    run,
    settle,
)
from twinfleet import (
    CallError,
    CallFailure,
    Context,
    Node,
    String,
    every,
    on_start,
    service,
    subscribe,
)
from twinfleet.runtime.contract.messages import NodeAlive, Violation, decode, encode
from twinfleet.runtime.contract.node import QOS_DEFAULT, QOS_LATCHED
from twinfleet.runtime.core.choosers import derive_seed
from twinfleet.runtime.core.node_core import MAX_GAP
from twinfleet.runtime.core.statistics import Rejection
from twinfleet.runtime.host.clock import ManualClock
from twinfleet.runtime.host.keys import topic_key
from twinfleet.runtime.host.node_host import NodeHost
from twinfleet.runtime.host.transport import LoopbackTransport, TransportStatistics


class Fragile(Node):
    """Raises on odd numbers, counts even ones; watches liveliness."""

    def initial_state(self) -> Log:
        return Log()

    @subscribe("/nums")
    def on_num(self, ctx: Context, msg: Num) -> None:
        if msg.value % 2:
            raise RuntimeError(f"odd {msg.value}")
        self.state.seen.append(msg.value)

    @subscribe("/_liveliness")
    def on_alive(self, ctx: Context, msg: NodeAlive) -> None:
        self.state.seen.append(msg)


class LatchedListener(Node):
    def initial_state(self) -> Log:
        return Log()

    @subscribe("/map", qos=QOS_LATCHED)
    def on_map(self, ctx: Context, msg: String) -> None:
        self.state.seen.append(msg.data)


def test_start_after_and_timer_priorities() -> None:
    async def body() -> list[Any]:
        h = Harness()
        node = Recorder("rec")
        await h.start(node)
        await h.advance(200)
        await h.stop()
        return node.state.seen

    assert run(body()) == [(0, "start"), (50, "later x"), (100, "tick p1"), (100, "tick p2"),
                           (200, "tick p1"), (200, "tick p2")]


def test_simultaneous_messages_run_by_priority_then_arrival() -> None:
    async def body() -> list[Any]:
        h = Harness()
        node = Recorder("rec")
        await h.start(node)
        raw = await h.raw()
        for topic, value in (("/low", 1), ("/high", 2), ("/low", 3), ("/high", 4)):
            raw.put(topic_key(FLEET, topic), encode(Num(value), seq=value), QOS_DEFAULT)
        await settle(*h.hosts)
        await h.stop()
        return [event for _, event in node.state.seen[1:]]

    assert run(body()) == ["high 2", "high 4", "low 1", "low 3"]


def test_every_is_drift_free_and_counts_pending_timers() -> None:
    async def body() -> tuple[list[int], int]:
        h = Harness()
        node = Recorder("rec")
        host = await h.start(node)
        for _ in range(7):
            await h.advance(143)  # steps that do not divide the period
        pending = host.statistics().timers_pending
        await h.stop()
        return [t for t, e in node.state.seen if e == "tick p1"], pending

    ticks, pending = run(body())
    assert ticks == [100, 200, 300, 400, 500, 600, 700, 800, 900, 1000]
    assert pending == 2  # the two @every timers, re-armed


def test_service_call_and_reply() -> None:
    async def body() -> list[Any]:
        h = Harness()
        await h.start(Doubler("doubler"))
        asker = Asker("asker")
        await h.start(asker)
        await h.stop()
        return asker.state.seen

    assert run(body()) == [Num(42)]


def test_call_without_server_gets_no_server_error() -> None:
    async def body() -> list[Any]:
        h = Harness()
        asker = Asker("asker", AskerParams(service="/missing"))
        await h.start(asker)
        await h.stop()
        return asker.state.seen

    assert run(body()) == [CallError("/missing", CallFailure.NO_SERVER, "no server")]


def test_call_timeout_is_a_clock_timer() -> None:
    async def body() -> tuple[list[Any], list[Any]]:
        h = Harness()
        mute = await h.raw()
        mute.serve(topic_key(FLEET, "/double"), lambda payload, respond: None)  # never answers
        asker = Asker("asker", AskerParams(timeout_ms=200))
        await h.start(asker)
        before = list(asker.state.seen)
        await h.advance(199)
        before += asker.state.seen
        await h.advance(1)
        await h.stop()
        return before, asker.state.seen

    before, after = run(body())
    assert before == []
    assert after == [CallError("/double", CallFailure.TIMEOUT, "timeout")]


def test_server_exception_becomes_call_error_and_server_keeps_serving() -> None:
    async def body() -> tuple[list[Any], list[Any], int]:
        h = Harness()
        server = await h.start(Doubler("doubler"))
        bad = Asker("bad", AskerParams(value=-1))
        good = Asker("good", AskerParams(value=5))
        await h.start(bad)
        await h.start(good)
        await h.stop()
        return bad.state.seen, good.state.seen, server.statistics().handler_errors

    bad, good, errors = run(body())
    assert bad == [CallError("/double", CallFailure.SERVER_ERROR, "server error: ValueError: negative")]
    assert good == [Num(10)]
    assert errors == 1


def test_handler_exception_is_logged_counted_published_and_node_keeps_serving() -> None:
    async def body() -> tuple[list[Any], Any, list[Violation], str]:
        h = Harness()
        violations: list[Violation] = []
        raw = await h.raw()
        raw.subscribe(topic_key(FLEET, "/violations"),
                      lambda k, p: violations.append(decode(p).msg), QOS_DEFAULT)
        node = Fragile("fragile")
        host = await h.start(node)
        for seq, value in enumerate((2, 3, 4), start=1):
            raw.put(topic_key(FLEET, "/nums"), encode(Num(value), seq=seq), QOS_DEFAULT)
        await settle(*h.hosts)
        await h.stop()
        return node.state.seen, host.statistics(), violations, h.out.getvalue()

    seen, stats, violations, _ = run(body())
    assert [v for v in seen if isinstance(v, int)] == [2, 4]
    assert stats.handler_errors == 1
    assert violations == [Violation("fragile", "on_num", "RuntimeError: odd 3")]


def test_stop_on_error_stops_the_host() -> None:
    async def body() -> tuple[bool, list[Any]]:
        h = Harness()
        raw = await h.raw()
        node = Fragile("fragile")
        host = await h.start(node, stop_on_error=True)
        for seq, value in enumerate((3, 4), start=1):
            raw.put(topic_key(FLEET, "/nums"), encode(Num(value), seq=seq), QOS_DEFAULT)
        await asyncio.wait_for(h.tasks[0], 5)  # run() returns by itself
        return host.failed, node.state.seen

    failed, seen = run(body())
    assert failed
    assert 4 not in seen


def test_fail_effect_is_counted_and_published() -> None:
    async def body() -> tuple[list[Any], int]:
        h = Harness()
        violations: list[Any] = []
        raw = await h.raw()
        raw.subscribe(topic_key(FLEET, "/violations"),
                      lambda k, p: violations.append(decode(p).msg), QOS_DEFAULT)
        server = await h.start(Doubler("doubler"))
        asker = Asker("asker", AskerParams(value=13))
        await h.start(asker)
        await h.stop()
        return violations, server.statistics().failures

    violations, failures = run(body())
    assert violations == [Violation("doubler", "", "unlucky number")]
    assert failures == 1


def test_undecodable_payload_is_counted_and_dropped() -> None:
    async def body() -> tuple[list[Any], Any]:
        h = Harness()
        raw = await h.raw()
        node = Fragile("fragile")
        host = await h.start(node)
        raw.put(topic_key(FLEET, "/nums"), b"\xc1 not msgpack", QOS_DEFAULT)
        raw.put(topic_key(FLEET, "/nums"), encode(String("wrong type?")), QOS_DEFAULT)
        raw.put(topic_key(FLEET, "/nums"), encode(Num(8), seq=3), QOS_DEFAULT)
        await settle(*h.hosts)
        await h.stop()
        return node.state.seen, host.statistics()

    seen, stats = run(body())
    assert 8 in seen
    assert stats.dropped_undecodable == 1
    assert stats.received == 3


def test_sequence_gaps_are_counted_per_sender() -> None:
    async def body() -> int:
        h = Harness()
        raw = await h.raw()
        host = await h.start(Fragile("fragile"))
        for sender, seq in (("a", 1), ("b", 1), ("a", 2), ("a", 5), ("b", 2), ("a", 6)):
            raw.put(topic_key(FLEET, "/nums"), encode(Num(2), seq=seq, sender=sender), QOS_DEFAULT)
        await settle(*h.hosts)
        await h.stop()
        return host.statistics().gaps

    assert run(body()) == 2


def test_a_forged_sequence_leap_is_not_counted_as_lost_messages() -> None:
    async def body() -> tuple[int, int]:
        h = Harness()
        raw = await h.raw()
        host = await h.start(Fragile("fragile"))
        for seq in (1, 2, 4, 2 + MAX_GAP * 1000, 3 + MAX_GAP * 1000, 6 + MAX_GAP * 1000):
            raw.put(topic_key(FLEET, "/nums"), encode(Num(2), seq=seq, sender="a"), QOS_DEFAULT)
        await settle(*h.hosts)
        await h.stop()
        stats = host.statistics()
        return stats.gaps, stats.sequence_jumps

    assert run(body()) == (1 + 2, 1)  # 3 is lost, then one leap, then 4 and 5 are lost


def test_liveliness_changes_reach_a_liveliness_subscriber() -> None:
    async def body() -> list[Any]:
        h = Harness()
        node = Fragile("watcher")
        await h.start(node)
        other = LatchedListener("other")
        await h.start(other)
        h.hosts[1].stop()
        await h.tasks[1]
        await h.hosts[1].transport.close()
        await settle(h.hosts[0])
        h.hosts.pop(1)
        h.tasks.pop(1)
        await h.stop()
        return [m for m in node.state.seen if isinstance(m, NodeAlive)]

    assert run(body()) == [NodeAlive("watcher", True), NodeAlive("other", True),
                           NodeAlive("other", False)]


def test_latched_topic_reaches_a_late_joiner() -> None:
    class MapPublisher(Node):
        publications = {"/map": QOS_LATCHED}

        @on_start
        def start(self, ctx: Context) -> None:
            ctx.publish("/map", String("v1"))
            ctx.publish("/map", String("v2"))

    async def body() -> list[str]:
        h = Harness()
        await h.start(MapPublisher("map_server"))
        late = LatchedListener("late")
        await h.start(late)
        await h.stop()
        return late.state.seen

    assert run(body()) == ["v2"]


def test_on_start_waits_for_peers() -> None:
    async def body() -> tuple[list[Any], list[Any]]:
        h = Harness()
        node = Recorder("rec")
        await h.start(node, wait_for=("rec", "peer"))
        before = list(node.state.seen)
        await h.start(Doubler("peer"))
        await h.stop()
        return before, node.state.seen

    before, after = run(body())
    assert before == []
    assert (0, "start") in after


def test_derive_seed_is_stable_and_distinct() -> None:
    assert derive_seed(1, "r1") == derive_seed(1, "r1")
    assert derive_seed(1, "r1") != derive_seed(1, "r2")
    assert derive_seed(1, "r1") != derive_seed(2, "r1")
    expected = int.from_bytes(hashlib.sha256(b"1:r1").digest()[:8], "big")
    assert derive_seed(1, "r1") == expected  # independent of PYTHONHASHSEED


def test_choose_is_reproducible_for_a_seed() -> None:
    class Picker(Node):
        def initial_state(self) -> Log:
            return Log()

        @every(10)
        def tick(self, ctx: Context) -> None:
            self.state.seen.append(ctx.choose(range(1000)))

    async def picks() -> list[int]:
        h = Harness()
        node = Picker("picker")
        await h.start(node)
        await h.advance(100)
        await h.stop()
        return node.state.seen

    first, second = run(picks()), run(picks())
    assert first == second
    assert len(set(first)) > 1



def test_manual_clock_runs_due_callbacks_in_time_then_schedule_order() -> None:
    clock = ManualClock(10)
    fired: list[str] = []
    clock.call_at(30, fired.append, "c")
    clock.call_at(20, fired.append, "a")
    clock.call_at(20, fired.append, "b")
    clock.call_at(5, fired.append, "past")  # due in the past: runs at the next advance
    handle = clock.call_at(25, fired.append, "cancelled")
    handle.cancel()
    assert clock.advance(0) == 1
    clock.advance(15)
    assert fired == ["past", "a", "b"]
    assert clock.now_ms() == 25
    assert clock.pending() == 1


def test_keep_last_drops_the_oldest_waiting_messages_and_counts_them() -> None:
    async def body() -> tuple[list[Any], Any]:
        h = Harness()
        raw = await h.raw()
        node = Shallow("shallow")
        host = await h.start(node)
        for seq in range(1, 11):  # ten arrive before the host gets to run any of them
            raw.put(topic_key(FLEET, "/nums"), encode(Num(seq), seq=seq, sender="a"), QOS_DEFAULT)
        for seq in range(1, 4):
            raw.put(topic_key(FLEET, "/other"), encode(Num(seq), seq=seq, sender="a"), QOS_DEFAULT)
        await settle(*h.hosts)
        raw.put(topic_key(FLEET, "/nums"), encode(Num(11), seq=11, sender="a"), QOS_DEFAULT)
        await settle(*h.hosts)
        await h.stop()
        return node.state.seen, host.statistics()

    seen, stats = run(body())
    assert seen == [8, 9, 10, -3, 11]  # arrival order kept among the survivors
    assert stats.dropped_best_effort == 0
    assert stats.dropped_keep_last == 7 + 2
    assert stats.received == 14
    assert stats.gaps == 0  # dropped on purpose by the subscriber, not lost on the way
    assert stats.inbox_depth == 0


def test_keep_last_loses_nothing_when_the_host_keeps_up() -> None:
    async def body() -> tuple[list[Any], Any]:
        h = Harness()
        raw = await h.raw()
        node = Shallow("shallow")
        host = await h.start(node)
        for seq in range(1, 21):
            raw.put(topic_key(FLEET, "/nums"), encode(Num(seq), seq=seq, sender="a"), QOS_DEFAULT)
            if seq % 3 == 0:
                await settle(*h.hosts)
        await settle(*h.hosts)
        await h.stop()
        return node.state.seen, host.statistics()

    seen, stats = run(body())
    assert seen == list(range(1, 21))
    assert stats.dropped_keep_last == 0


def test_statistics_report_the_transport_overflow() -> None:
    class Overflowing(LoopbackTransport):
        def statistics(self) -> TransportStatistics:
            return TransportStatistics(wakeups=1, overflow=5,
                                       refused={Rejection.FORGED: 2, Rejection.OVERSIZE: 1})

    async def body() -> Any:
        h = Harness()
        transport = Overflowing(h.bus)
        await transport.open()
        host = NodeHost(Shallow("s"), transport, h.clock, seed=1, fleet=FLEET, out=h.out)
        return host.statistics()

    stats = run(body())
    assert stats.dropped_overflow == 5
    assert (stats.rejected[Rejection.FORGED], stats.rejected[Rejection.OVERSIZE]) == (2, 1)


def test_best_effort_gaps_are_counted_as_drops_not_as_gaps() -> None:
    async def body() -> Any:
        h = Harness()
        raw = await h.raw()
        host = await h.start(Shallow("shallow"))
        for seq in (1, 2, 5, 6, 9):
            raw.put(topic_key(FLEET, "/other"), encode(Num(seq), seq=seq, sender="a"), QOS_DEFAULT)
            await settle(*h.hosts)
        await h.stop()
        return host.statistics()

    stats = run(body())
    assert (stats.gaps, stats.dropped_best_effort) == (0, 4)


class Overflower(Node):
    """Publishes and replies with an int msgpack cannot encode when asked to."""

    @subscribe("/nums")
    def on_num(self, ctx: Context, msg: Num) -> None:
        ctx.publish("/out", Num(msg.value * 2**64))

    @service("/double")
    def double(self, ctx: Context, req: Num) -> Num:
        return Num(req.value * 2**64)


def test_unencodable_effects_and_replies_are_handler_errors_not_crashes() -> None:
    async def body() -> tuple[list[Any], Any, list[Any], list[int]]:
        h = Harness()
        raw = await h.raw()
        host = await h.start(Overflower("overflower"))
        violations: list[Any] = []
        out_seqs: list[int] = []
        raw.subscribe(topic_key(FLEET, "/violations"),
                      lambda k, p: violations.append(decode(p).msg), QOS_DEFAULT)
        raw.subscribe(topic_key(FLEET, "/out"), lambda k, p: out_seqs.append(decode(p).seq),
                      QOS_DEFAULT)
        raw.put(topic_key(FLEET, "/nums"), encode(Num(1), seq=1), QOS_DEFAULT)
        asker = Asker("asker")
        await h.start(asker)
        raw.put(topic_key(FLEET, "/nums"), encode(Num(0), seq=2), QOS_DEFAULT)  # still serving
        await settle(*h.hosts)
        await h.stop()
        return asker.state.seen, host.statistics(), violations, out_seqs

    seen, stats, violations, out_seqs = run(body())
    assert len(seen) == 1 and seen[0].failure is CallFailure.SERVER_ERROR
    assert seen[0].reason.startswith("server error: unencodable reply")
    assert stats.handler_errors == 2 and stats.handled == 3
    assert [v.handler for v in violations] == ["on_num", "double"]
    assert out_seqs == [1]  # the failed publish used no sequence number: receivers see no gap
