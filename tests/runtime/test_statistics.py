"""`NodeStatistics`: the typed record a node serves and the launcher judges; its strict wire
form; and `Status`, the one word list of verdicts."""

from __future__ import annotations

import dataclasses

import msgpack
import pytest

from tests.runtime.hosts import Num, Shallow
from twinfleet import message
from twinfleet.runtime.contract.kinds import Status
from twinfleet.runtime.contract.messages import encode
from twinfleet.runtime.contract.names import OPERATOR_SENDER
from twinfleet.runtime.core.guard import Rejected
from twinfleet.runtime.core.node_core import NodeCore
from twinfleet.runtime.core.statistics import (
    WIRE_NAMES,
    NodeStatistics,
    Outside,
    Rejection,
    StatisticsError,
)
from twinfleet.runtime.fleet.live_verdict import RESULT_WORDS, statistics_reasons
from twinfleet.runtime.fleet.node_main import read_statistics, statistics_payload

pytestmark = pytest.mark.timeout(30)


@message("test_msgs/Word")
class Word:
    text: str


BUSY = NodeStatistics(received=12, dropped_undecodable=1, handler_errors=2, failures=3, gaps=4,
                      inbox_depth=5, timers_pending=6, published=7, handled=8,
                      dropped_keep_last=9, dropped_overflow=10, dropped_best_effort=11,
                      sequence_jumps=12, dropped_lossless=13, stalls=14, max_lateness_ms=15,
                      stall_threshold_ms=16, external_input=21,
                      rejected={Rejection.FORGED: 17, Rejection.INVALID: 18,
                                Rejection.OVERSIZE: 19, Rejection.WRONG_TYPE: 20})

# Counters the live verdict does not judge: what a healthy run also counts, or a
# snapshot of the moment, or input from outside the fleet (rejected_external: an operator's
# forced sample, refused; external_input: the bridge's, taken; the verdict names both in a
# detail line). Every other field must make a run inconclusive.
NOT_JUDGED = {"rejected_external", "external_input", "received", "dropped_undecodable", "handler_errors", "failures", "inbox_depth",
              "timers_pending", "published", "handled", "dropped_keep_last",
              "dropped_best_effort", "sequence_jumps", "max_lateness_ms", "stall_threshold_ms",
              "played", "outside_input"}  # said in the verdict's details, never inconclusive


def test_the_wire_form_reads_back_as_the_same_record():
    assert NodeStatistics.from_dict(BUSY.to_dict()) == BUSY
    assert read_statistics(statistics_payload(BUSY)) == BUSY
    assert NodeStatistics.from_dict(NodeStatistics().to_dict()) == NodeStatistics()


def test_the_wire_form_keeps_the_printed_counter_names_in_order():
    wire = BUSY.to_dict()
    assert set(wire) == WIRE_NAMES
    assert list(wire)[:3] == ["received", "dropped_undecodable", "handler_errors"]
    assert list(wire)[-8:] == ["rejected_forged", "rejected_invalid", "rejected_oversize",
                               "rejected_wrong_type", "rejected_replayed", "rejected_recorded",
                               "wrong_types", "outside_input"]
    assert BUSY.line().startswith("received=12 dropped_undecodable=1 handler_errors=2 ")
    assert " rejected_oversize=19 rejected_wrong_type=20 " in BUSY.line()


def test_outside_input_reads_back_and_a_bad_entry_is_refused():
    fed = NodeStatistics(outside_input=((Outside.OPERATOR, "/chatter", 2),))
    assert NodeStatistics.from_dict(fed.to_dict()) == fed
    assert fed.to_dict()["outside_input"] == [["OPERATOR", "/chatter", 2]]
    for bad in ([["SOMEONE", "/chatter", 2]], [["OPERATOR", "/chatter", "2"]], "x"):
        with pytest.raises(StatisticsError, match="outside_input must be a list"):
            NodeStatistics.from_dict({**fed.to_dict(), "outside_input": bad})


def test_an_unknown_counter_is_refused_not_ignored():
    wire = {**BUSY.to_dict(), "rejected_some_future_reason": 1}
    with pytest.raises(StatisticsError, match="unknown counters 'rejected_some_future_reason'"):
        NodeStatistics.from_dict(wire)


@pytest.mark.parametrize("name", ["gaps", "stalls", "rejected_forged", "dropped_lossless"])
def test_a_missing_counter_is_refused_not_read_as_zero(name):
    wire = BUSY.to_dict()
    del wire[name]
    with pytest.raises(StatisticsError, match=f"missing counters {name}"):
        NodeStatistics.from_dict(wire)


def test_a_renamed_counter_is_named_both_ways():
    wire = BUSY.to_dict()
    wire["sequence_gaps"] = wire.pop("gaps")
    with pytest.raises(StatisticsError) as info:
        NodeStatistics.from_dict(wire)
    assert "unknown counters 'sequence_gaps'" in str(info.value)
    assert "missing counters gaps" in str(info.value)


@pytest.mark.parametrize("bad", [None, [1, 2], "gaps=1", {"gaps": "1"}, {"gaps": True},
                                 {"gaps": 1.5}])
def test_anything_but_a_map_of_integers_is_refused(bad):
    data = bad if not isinstance(bad, dict) else {**BUSY.to_dict(), **bad}
    with pytest.raises(StatisticsError):
        NodeStatistics.from_dict(data)


def test_a_payload_that_is_not_msgpack_is_refused():
    with pytest.raises(StatisticsError, match="not a msgpack map"):
        read_statistics(b"\xc1")
    with pytest.raises(StatisticsError, match="expected a map"):
        read_statistics(msgpack.packb([1, 2, 3]))


def test_rejections_are_keyed_by_reason_and_always_complete():
    partial = NodeStatistics(rejected={Rejection.OVERSIZE: 2})
    assert dict(partial.rejected) == {Rejection.FORGED: 0, Rejection.INVALID: 0,
                                      Rejection.OVERSIZE: 2, Rejection.WRONG_TYPE: 0,
                                      Rejection.REPLAYED: 0, Rejection.RECORDED: 0}
    with pytest.raises(TypeError):
        partial.rejected[Rejection.FORGED] = 1  # type: ignore[index]
    with pytest.raises(StatisticsError, match="Rejection members"):
        NodeStatistics(rejected={"rejected_forged": 1})  # type: ignore[dict-item]


def test_the_core_adds_what_its_transport_refused_to_its_own_rejections():
    core = NodeCore(Shallow("s"), seed=1)
    core.start(0)
    receive = core.receiver("on_num")
    receive(encode(Num(1), seq=1, sender="a"), 0)
    with pytest.raises(Rejected):  # not the Num the handler declares: refused, counted
        receive(encode(Word("x"), seq=2, sender="a"), 0)
    stats = core.statistics(dropped_overflow=3, refused={Rejection.FORGED: 5})
    assert stats.dropped_overflow == 3
    assert stats.rejected[Rejection.FORGED] == 5
    assert stats.rejected[Rejection.WRONG_TYPE] == 1


def test_every_counter_is_judged_by_the_live_verdict_or_listed_as_not_judged():
    """A new counter needs a decision: judged (a reason line) or listed in NOT_JUDGED."""
    fields = {f.name for f in dataclasses.fields(NodeStatistics)}
    judged = fields - NOT_JUDGED - {"wrong_types"}  # a breach, not a reason: see below
    assert NOT_JUDGED.issubset(fields)
    for name in judged:
        value = ({reason: 1 for reason in Rejection} if name == "rejected" else 1)
        reasons = statistics_reasons("n", NodeStatistics(**{name: value}))
        assert reasons, f"{name} makes no run inconclusive"
    for name in NOT_JUDGED:
        assert statistics_reasons("n", NodeStatistics(**{name: 1})) == [], name


def test_one_status_word_list_for_the_checker_and_the_live_verdict():
    assert [s.value for s in Status] == ["holds", "violated", "unknown", "contract breach",
                                         "error", "inconclusive", "interrupted"]
    assert {s: s.exit_code for s in Status} == {
        Status.HOLDS: 0, Status.VIOLATED: 1, Status.UNKNOWN: 2, Status.BREACH: 4,
        Status.ERROR: 2, Status.INCONCLUSIVE: 3, Status.INTERRUPTED: 130}
    assert RESULT_WORDS == {Status.HOLDS: "PASSED", Status.VIOLATED: "FAILED",
                            Status.ERROR: "ERROR", Status.INCONCLUSIVE: "INCONCLUSIVE",
                            Status.INTERRUPTED: "interrupted", Status.BREACH: "CONTRACT BREACH"}
    assert f"{Status.BREACH}" == "contract breach" and Status("holds") is Status.HOLDS


def test_a_refused_sample_an_operator_sent_is_external_input_not_a_rejection():
    core = NodeCore(Shallow("s"), seed=1)
    core.start(0)
    receive = core.receiver("on_num")
    with pytest.raises(Rejected):  # `topic pub --force` of the wrong type: still refused
        receive(encode(Word("x"), seq=1, sender=OPERATOR_SENDER), 0)
    stats = core.statistics()
    assert stats.rejected_external == 1
    assert stats.rejected[Rejection.WRONG_TYPE] == 0
    assert statistics_reasons("s", stats) == []
