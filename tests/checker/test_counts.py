"""Exact state and transition counts of small models, computed by hand.

Notation in the comments: a world is "node states {pending events}"; "->"
is one transition. Start handlers run while building the initial world and
are not transitions. RMC-style transitions = transitions + initial states.
"""

from __future__ import annotations

import pytest

from tests.checker.helpers import counts, node, run, scenario
from twinfleet.checker import PropertySet, System
from twinfleet.checker.driver import load
from twinfleet.checker.world import World

pytestmark = pytest.mark.timeout(30)


def test_ping_pong_counts(tmp_path):
    # S0 sent=1 recv=0 {ping} -> S1 1,1 {pong} -> S2 2,1 {ping} -> S3 2,2 {pong}
    # -> S4 3,2 {ping} -> S5 3,3 {pong} -> S6 3,3 {} (on_pong with sent=3 sends nothing).
    # 7 states, 6 transitions, RMC 7; depth 6. Deterministic, so bfs == dfs.
    path = scenario(tmp_path, [node("ping", "Ping", rounds=3), node("pong", "Pong")],
                    properties=[{"name": "bounded", "kind": "invariant",
                                 "expr": "ping.sent - pong.received <= 1"}])
    for search in ("bfs", "dfs"):
        result = run(path, search=search)
        assert result.status == "holds"
        assert counts(result) == (7, 6, 7)
        assert result.statistics.depth == 6


@pytest.mark.parametrize(("semantics", "expected"), [
    # ros: TwoSender's 1 and 2 keep their order, 4 interleaves anywhere.
    # S0 0{1,2,4}: ->1 (1{2,4}), ->4 (4{1,2})          2 transitions
    # 1{2,4}: ->3{4}, ->5{2};   4{1,2}: ->5{2} (only 1: FIFO)   3
    # 3{4} -> 7{};  5{2} -> 7{}                          2
    # states 0,1,4,3,5,7 = 6; transitions 7; RMC 8
    ("ros", (6, 7, 8)),
    # rebeca: 1, 2 and 4 are all alternatives (R5).
    # S0: 3 transitions to 1{2,4}, 2{1,4}, 4{1,2}; each of those: 2 -> 6 transitions
    # reaching 3{4}, 5{2}, 6{1}; each of those: 1 -> 7{}.
    # states 1+3+3+1 = 8; transitions 3+6+3 = 12; RMC 13
    ("rebeca", (8, 12, 13)),
])
def test_same_model_under_ros_and_rebeca(tmp_path, semantics, expected):
    path = scenario(tmp_path, [node("two", "TwoSender"), node("four", "FourSender"),
                               node("sum", "Summer")], semantics=semantics,
                    properties=[{"name": "total_ok", "kind": "invariant",
                                 "expr": "sum.total in (0, 1, 2, 3, 4, 5, 6, 7)"}])
    result = run(path)
    assert result.status == "holds"
    assert result.semantics == semantics
    assert counts(result) == expected


@pytest.mark.parametrize(("semantics", "expected"), [
    # /add4 has handler priority -1: it runs before simultaneous /add messages.
    # ros: 0{1,2,4} -> 4{1,2} -> 5{2} -> 7{}: 4 states, 3 transitions.
    ("ros", (4, 3, 4)),
    # rebeca: 0 -> 4{1,2} -> 5{2} | 6{1} -> 7{}: 5 states, 1+2+2 = 5 transitions.
    ("rebeca", (5, 5, 6)),
])
def test_handler_priority(tmp_path, semantics, expected):
    path = scenario(tmp_path, [node("two", "TwoSender"), node("four", "FourSender"),
                               node("sum", "UrgentSummer")], semantics=semantics)
    assert counts(run(path)) == expected


@pytest.mark.parametrize(("semantics", "priorities", "expected"), [
    # Two nodes each with a flag timer at t=0: S0 -> f1 first | f2 first -> both: 4 states,
    # 4 transitions.
    ("ros", (None, None), (4, 4, 5)),
    ("rebeca", (None, None), (4, 4, 5)),
    # rebeca R4: f1 (priority 1) runs before f2 (priority 2): S0 -> f1 -> f2, 3 states, 2.
    ("rebeca", (1, 2), (3, 2, 3)),
    # ros ignores node-instance priorities.
    ("ros", (1, 2), (4, 4, 5)),
])
def test_node_instance_priority(tmp_path, semantics, priorities, expected):
    path = scenario(tmp_path, [node("f1", "Flagger", priorities[0]),
                               node("f2", "Flagger", priorities[1])], semantics=semantics)
    assert counts(run(path)) == expected


@pytest.mark.parametrize(("global_priority", "expected"), [
    # f1.flag has handler priority 0, f2.flag priority 1, on different nodes.
    # rebeca (local priorities): both orders, 4 states, 4 transitions.
    (False, (4, 4, 5)),
    # rebeca with global_priority: f1's message is compared with f2's across nodes and
    # runs first: S0 -> f1 -> f2, 3 states, 2 transitions.
    (True, (3, 2, 3)),
])
def test_global_priority(tmp_path, global_priority, expected):
    path = scenario(tmp_path, [node("f1", "Flagger"), node("f2", "SlowFlagger")],
                    semantics="rebeca", global_priority=global_priority)
    assert counts(run(path)) == expected


@pytest.mark.parametrize(("nodes", "semantics", "expected"), [
    # Stateless timers A (100 ms) and B (150 ms); a world is (A, B) due times relative to t*.
    # S0 (0,50) -A-> S1 (50,0) -B-> S2 (0,100) -A-> S3 (0,0) at t=300:
    #   -A-> S4 (100,0) -B-> back to (0,50) = S0;   -B-> S5 (0,150) -A-> S0.
    # 6 states, 7 transitions: time-shift equivalence closes the infinite run.
    ("two", "ros", (6, 7, 8)),
    ("two", "rebeca", (6, 7, 8)),
    # Both timers on one node: under ros at t=300 tock (set at t=150) fires before tick
    # (set at t=200): S4 is unreachable, 5 states, 5 transitions. rebeca: both orders.
    ("one", "ros", (5, 5, 6)),
    ("one", "rebeca", (6, 7, 8)),
])
def test_time_shift_closes_periodic_timers(tmp_path, nodes, semantics, expected):
    entries = ([node("a", "TickA"), node("b", "TickB")] if nodes == "two"
               else [node("ab", "TickBoth")])
    assert counts(run(scenario(tmp_path, entries, semantics=semantics))) == expected


def test_counter_modulo_closes_and_unbounded_hits_limit(tmp_path):
    # count 0 -> 1 -> 2 -> 0 (mod 3) every 100 ms: 3 states, 3 transitions.
    path = scenario(tmp_path, [node("c", "Counter", modulo=3)], name="mod")
    assert counts(run(path)) == (3, 3, 4)
    # Without the modulo every count is a new state: only a limit stops the search.
    path = scenario(tmp_path, [node("c", "Counter", modulo=0)], name="inf")
    result = run(path, max_states=50)
    assert result.status == "unknown"
    assert "max-states 50" in result.reason
    assert result.exit_code == 2
    assert result.statistics.states == 50
    result = run(path, max_depth=10)
    assert result.status == "unknown"
    assert "max-depth 10" in result.reason


@pytest.mark.parametrize(("options", "expected"), [
    # Picker: S0 {pick@1} -> one world per option. k options = k transitions.
    ({}, (4, 3, 4)),
    ({"options": [7]}, (2, 1, 2)),
    # two options lead to the same state: 3 transitions (revisit counted), 3 states.
    ({"options": [1, 1, 2]}, (3, 3, 4)),
    # 3 x 2 nested choices: 6 transitions, values 10,110,20,120,30,130: 7 states.
    ({"second": [0, 100]}, (7, 6, 7)),
])
def test_choose_branches(tmp_path, options, expected):
    path = scenario(tmp_path, [node("p", "Picker", **options)])
    assert counts(run(path)) == expected


def test_choose_k_successors_exactly(tmp_path):
    path = scenario(tmp_path, [node("p", "Picker", options=[10, 20, 30, 40])])
    system = System(load(path))
    (init,) = system.initial()
    succ = list(system.successors(init.world))
    assert [t.step.choices for t in succ] == [(0,), (1,), (2,), (3,)]
    assert [t.step.options for t in succ] == [(4,), (4,), (4,), (4,)]
    assert [system.decode(0, t.world.states[0]).value for t in succ] == [10, 20, 30, 40]


@pytest.mark.parametrize(("service", "expected"), [
    # S0 {request->adder @0} -> S1 {reply->client @0} -> S2 result=42 {}: 3 states, 2.
    ("/add_two", (3, 2, 3)),
    # No server: the CallError's reason is a branch ("no server" or "timeout", as Zenoh
    # gives up early or at the timeout live): S0 {CallError no server @50},
    # S0' {CallError timeout @50} -> S1 errors=1 {}: 3 states, 2 transitions.
    ("/nobody", (3, 2, 4)),
])
def test_service_call(tmp_path, service, expected):
    path = scenario(tmp_path, [node("client", "Client", service=service), node("adder", "Adder")],
                    properties=[{"name": "answered", "kind": "eventually",
                                 "expr": "client.result == 42 or client.errors == 1"}])
    result = run(path)
    assert result.status == "holds"
    assert counts(result) == expected


def test_latency_branches(tmp_path):
    # Ping-pong with latency [0, 1]: every message takes 0 or 1 ms, each a branch.
    # Worlds differ only in the pending message's due time relative to t*, which time
    # shift erases: still 7 states. The start handler's ping gives 2 initial worlds (same
    # digest); on_ping, on_pong, on_ping, on_pong, on_ping each send one message: 2 variants
    # each = 10 transitions; the last on_pong sends nothing: 1. Transitions 11, RMC 11 + 2.
    path = scenario(tmp_path, [node("ping", "Ping", rounds=3), node("pong", "Pong")],
                    latency=[0, 1])
    system_latency = System(load(path)).rules.latency
    assert system_latency == (0, 1)
    result = run(path)
    assert counts(result) == (7, 11, 13)
    assert result.statistics.initial_states == 2


def test_time_shift_digest_ignores_offset():
    a = World(0, (b"x",), ())
    b = World(500, (b"x",), ())
    assert a.digest == b.digest
    assert PropertySet(()).names()[-1].startswith("no_failure")
