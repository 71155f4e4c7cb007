"""Fault injection, deadlines, queue bounds and --check-determinism, counted by hand.

Each fault kind: (1) it changes the explored states of ping-pong (exact counts,
derived in the comments; compare the fault-free 7 states / 6 transitions of
test_counts.test_ping_pong_counts), and (2) on a scenario built for it, it turns
"holds" into a violation whose trace replays.

Ping-pong notation: (ping.sent, pong.received){pending}, c1 = one crash so far.
"""

from __future__ import annotations

import pytest

from tests.checker.helpers import counts, node, replay_confirms, run, scenario, steps
from twinfleet.checker import PropertySet, System
from twinfleet.checker.driver import load
from twinfleet.runtime.scenario.spec import ScenarioError

pytestmark = pytest.mark.timeout(60)

PING_PONG = [node("ping", "Ping", rounds=3), node("pong", "Pong")]
BOUNDED = [{"name": "bounded", "kind": "invariant", "expr": "ping.sent - pong.received <= 1"}]
FINISHED = "ping.sent == 3 and pong.received == 3"


def test_drop_changes_states_and_deadlocks(tmp_path):
    # drop /pong: each on_ping has two variants, the pong delivered or lost.
    # S0 (1,0){ping} -> S1 (1,1){pong} | D1 (1,1){}; S1 -> S2 (2,1){ping}
    # S2 -> S3 (2,2){pong} | D3 (2,2){}; S3 -> S4 (3,2){ping}
    # S4 -> S5 (3,3){pong} | (3,3){} = S6; S5 -> S6.  9 states, 2+1+2+1+2+1 = 9 transitions.
    path = scenario(tmp_path, PING_PONG, name="drop", faults={"drop": ["/pong"]})
    assert counts(run(path)) == (9, 9, 10)
    props = [{"name": "finishes", "kind": "deadlock", "expr": FINISHED}]
    ok = run(scenario(tmp_path, PING_PONG, name="nodrop", properties=props))
    assert ok.status == "holds"
    result = run(scenario(tmp_path, PING_PONG, name="drop2", properties=props,
                          faults={"drop": ["/pong"]}))
    assert result.status == "violated"
    assert result.violation.property == "finishes"
    assert steps(result) == [("pong", "on_ping", (1,))]
    assert result.trace["steps"][0]["faults"] == ["/pong to ping: dropped"]
    assert replay_confirms(result)


def test_dropped_service_request_times_out(tmp_path):
    # Client calls /add_two (timeout 50 ms). Delivered: S0 -> request -> reply -> result 42.
    # Lost (a branch of the start handler: a second initial world): CallError "timeout"
    # at t=50 -> errors=1. States: 3 + 2 = 5, transitions 2 + 1 = 3, initial worlds 2.
    nodes = [node("client", "Client"), node("adder", "Adder")]
    props = [{"name": "answered", "kind": "eventually", "expr": "client.result == 42"}]
    path = scenario(tmp_path, nodes, name="svc", faults={"drop": ["/add_two"]})
    result = run(path)
    assert counts(result) == (5, 3, 5)
    assert result.statistics.initial_states == 2
    assert run(scenario(tmp_path, nodes, name="svc_ok", properties=props)).status == "holds"
    result = run(scenario(tmp_path, nodes, name="svc_bad", properties=props,
                          faults={"drop": ["/add_two"]}))
    assert result.status == "violated"
    assert result.violation.shape == "terminal"
    assert steps(result) == [("client", "on_reply", ())]
    assert "timeout" in result.trace["steps"][0]["args"]
    assert replay_confirms(result)


def test_duplicate_changes_states_and_breaks_an_invariant(tmp_path):
    # duplicate /pong under ros: ping gets one or two pongs, and a second pong while
    # sent < 3 sends another ping. Messages carry numbers (ping k, pong echoes k), so
    # {pong1, pong2} and {pong2, pong2} differ. By hand:
    # S0 (1,0){ping1} -> A (1,1){pong1} | B (1,1){pong1,pong1};  A -> C (2,1){ping2}
    # B -> E (2,1){pong1,ping2};  C -> F (2,2){pong2} | G (2,2){pong2,pong2}
    # E -> H (3,1){ping2,ping3} | G' (2,2){pong1,pong2} | I (2,2){pong1,pong2,pong2}
    # F -> J (3,2){ping3};  G -> K (3,2){pong2,ping3};  G' -> K
    # H (rank-0 ping only) -> K | L (3,2){pong2,pong2,ping3};  I -> L
    # J -> N (3,3){pong3} | O (3,3){pong3,pong3}
    # K -> J | O' (3,3){pong2,pong3} | P' (3,3){pong2,pong3,pong3}
    # L -> K | P'' (3,3){pong2,pong2,pong3} | Q (3,3){pong2,pong2,pong3,pong3}
    # N -> R (3,3){};  O -> N;  O' -> N;  P' -> O;  P'' -> O';  Q -> P'.
    # 20 states; transitions 2+1+1+2+3+1+1+1+2+1+2+3+3+1+1+1+1+1+1 = 29.
    path = scenario(tmp_path, PING_PONG, name="dup", faults={"duplicate": ["/pong"]})
    assert counts(run(path)) == (20, 29, 30)
    props = [{"name": "no_echo", "kind": "invariant", "expr": "pong.received <= ping.sent"}]
    assert run(scenario(tmp_path, PING_PONG, name="dup_ok", properties=props)).status == "holds"
    result = run(scenario(tmp_path, PING_PONG, name="dup_bad", properties=props,
                          faults={"duplicate": ["/ping"]}))
    # The start handler's ping is duplicated (initial choice 1): pong receives it twice.
    assert result.status == "violated"
    assert result.violation.property == "no_echo"
    assert result.trace["initial"]["choices"] == [1]
    assert steps(result) == [("pong", "on_ping", ()), ("pong", "on_ping", ())]
    assert replay_confirms(result)


def test_drop_and_duplicate_together_are_three_branches(tmp_path):
    path = scenario(tmp_path, PING_PONG, name="both",
                    faults={"drop": ["/pong"], "duplicate": ["/pong"]})
    system = System(load(path))
    (init,) = system.initial()
    assert [t.step.options for t in system.successors(init.world)] == [(3,), (3,), (3,)]


@pytest.mark.parametrize(("durable", "expected"), [
    # Pong may crash once, non-durable: a crash in S0..S5 (worlds with something pending)
    # loses the events to pong and resets pong.received to 0.
    # S0 -> (1,0){} c1.  S1 (1,1){pong} -> (1,0){pong} c1 -> (2,0){ping} -> (2,1){pong}
    # -> (3,1){ping} -> (3,2){pong} -> (3,2){}: 6 states, 5 transitions after the crash.
    # S2 -> (2,0){} c1.  S3 -> (2,0){pong} c1 -> (3,0){ping} -> (3,1){pong} -> (3,1){}: 4, 3.
    # S4 -> (3,0){} c1.  S5 -> (3,0){pong} c1 -> (3,0){} c1 (seen).
    # States 7 + 14 = 21; transitions 6 + 6 crashes + 5 + 3 + 1 = 21.
    (False, (21, 21, 22)),
    # Durable: pong keeps received. S0 -> (1,0){} c1; S1 -> (1,1){pong} c1 -> (2,1){ping}
    # -> (2,2){pong} -> (3,2){ping} -> (3,3){pong} -> (3,3){}: 6 states, 5 transitions;
    # S2 -> (2,1){} c1; S3 -> (2,2){pong} c1 (seen); S4 -> (3,2){} c1; S5 -> (3,3){pong} c1 (seen).
    # States 7 + 9 = 16; transitions 6 + 6 + 5 = 17.
    (True, (16, 17, 18)),
])
def test_crash_changes_states(tmp_path, durable, expected):
    crash = {"nodes": ["pong"], "max": 1, "durable": ["pong"] if durable else []}
    path = scenario(tmp_path, PING_PONG, name=f"crash{durable}", faults={"crash": crash})
    assert counts(run(path)) == expected


def test_crash_resets_state_and_breaks_an_invariant_unless_durable(tmp_path):
    assert run(scenario(tmp_path, PING_PONG, name="nocrash", properties=BOUNDED)).status == "holds"
    crash = {"nodes": ["pong"]}
    result = run(scenario(tmp_path, PING_PONG, name="crash", properties=BOUNDED,
                          faults={"crash": crash}))
    # (1,0) -on_ping-> (1,1) -on_pong-> (2,1) -crash pong-> (2,0): sent - received = 2.
    assert result.status == "violated"
    assert result.violation.property == "bounded"
    assert [(s["node"], s["kind"]) for s in result.trace["steps"]] == [
        ("pong", "delivery"), ("ping", "delivery"), ("pong", "crash")]
    assert "pong crashed and restarted" in result.trace["steps"][-1]["faults"][0]
    assert result.trace["steps"][-1]["changed"] == {"pong": {"received": 0}}
    assert replay_confirms(result)
    durable = {"nodes": ["pong"], "durable": ["pong"], "max": 2}
    kept = run(scenario(tmp_path, PING_PONG, name="durable", properties=BOUNDED,
                        faults={"crash": durable}))
    assert kept.status == "holds"


def test_crash_restart_reruns_start_handlers(tmp_path):
    # Picker sets a 1 ms timer at start. Crash it before the pick (world S0 only has the
    # timer pending): the timer is lost and re-set by the restarted start handler.
    # S0 {pick@1} -> 3 picks (3 states); crash -> {pick@2} c1 (same shape as S0, 1 crash)
    # -> 3 picks c1. States 1 + 3 + 1 + 3 = 8; transitions 3 + 1 + 3 = 7.
    path = scenario(tmp_path, [node("p", "Picker")], name="restart",
                    faults={"crash": {"nodes": ["p"]}})
    assert counts(run(path)) == (8, 7, 8)


def test_per_topic_latency_branches(tmp_path):
    # Only /ping messages take 0 or 1 ms: the start's ping (2 initial worlds, one digest)
    # and the two pings sent by on_pong (2 variants each). 7 states; transitions
    # 3 on_ping + 2 x 2 on_pong + 1 last on_pong = 8; RMC 8 + 2.
    path = scenario(tmp_path, PING_PONG, name="lat", latency={"/ping": [0, 1]})
    system = System(load(path))
    assert system.rules.latency is None
    assert system.rules.latency_range("/ping") == (0, 1)
    assert system.rules.latency_range("/pong") is None
    assert counts(run(path)) == (7, 8, 10)
    # A default with a per-topic exemption is the same model the other way round.
    other = scenario(tmp_path, PING_PONG, name="lat2",
                     latency={"default": [0, 1], "/pong": [0, 0]})
    assert counts(run(other)) == (7, 8, 10)


def test_latency_on_one_topic_makes_a_watchdog_fail(tmp_path):
    nodes = [node("hb", "Heartbeat"), node("dog", "Watchdog")]
    assert run(scenario(tmp_path, nodes, name="dog_ok")).status == "holds"
    assert run(scenario(tmp_path, nodes, name="dog_fast", latency={"/beat": [0, 4]})).status \
        == "holds"
    result = run(scenario(tmp_path, nodes, name="dog_slow", latency={"/beat": [0, 6]}))
    assert result.status == "violated"
    assert "heartbeat 1 missing at t=15" in result.violation.message
    assert replay_confirms(result)
    result = run(scenario(tmp_path, nodes, name="dog_drop", faults={"drop": ["/beat"]}))
    assert result.status == "violated"
    assert replay_confirms(result)


@pytest.mark.parametrize(("deadline", "status"), [(1, "violated"), (2, "holds")])
def test_deadline_miss(tmp_path, deadline, status):
    # /ping takes 0..2 ms; a ping due 2 ms after it was sent misses a 1 ms deadline.
    path = scenario(tmp_path, PING_PONG, name=f"dl{deadline}", latency={"/ping": [0, 2]},
                    deadline_ms={"/ping": deadline})
    result = run(path)
    assert result.status == status
    if status == "holds":
        # 7 states (lateness never differs); on_pong's pings 2 x 3 variants + 3 + 1 = 10.
        assert counts(result) == (7, 10, 13)
        assert "deadline (deadline miss: messages handled within /ping 2 ms)" in result.properties
        return
    assert result.violation.property == "deadline"
    assert result.violation.kind == "deadline miss"
    assert "1 ms after its deadline" in result.violation.message
    assert result.trace["initial"]["choices"] == [2]
    assert steps(result) == [("pong", "on_ping", ())]
    assert replay_confirms(result)


def test_deadline_default_applies_to_every_message(tmp_path):
    path = scenario(tmp_path, PING_PONG, name="dldef", latency=[0, 2], deadline_ms=1)
    result = run(path)
    assert result.violation.property == "deadline"
    assert replay_confirms(result)


@pytest.mark.parametrize(("bound", "status"), [(2, "violated"), (3, "holds")])
def test_queue_overflow(tmp_path, bound, status):
    # Burst sends 3 messages to the sink at t=1: 3 pending events at the sink.
    nodes = [node("burst", "Burst"), node("sink", "Sink")]
    result = run(scenario(tmp_path, nodes, name=f"q{bound}", queue_bound={"sink": bound}))
    assert result.status == status
    if status == "holds":
        # {burst@1} -> {3 at sink} -> 2 -> 1 -> 0: 5 states, 4 transitions.
        assert counts(result) == (5, 4, 5)
        return
    assert result.violation.property == "queue_bound"
    assert result.violation.kind == "queue overflow"
    assert "sink has 3 pending events at t=1 ms (bound 2)" in result.violation.message
    assert steps(result) == [("burst", "burst", ())]
    assert replay_confirms(result)


def test_queue_bound_default(tmp_path):
    nodes = [node("burst", "Burst"), node("sink", "Sink")]
    result = run(scenario(tmp_path, nodes, name="qd", queue_bound=2))
    assert result.violation.property == "queue_bound"
    result = run(scenario(tmp_path, nodes, name="qd2", queue_bound={"default": 2, "sink": 5}))
    assert result.status == "holds"


def test_a_counter_outside_self_state_is_a_contract_breach_by_default(tmp_path):
    path = scenario(tmp_path, [node("f", "Flaky")], name="flaky")
    assert run(path, verify=False).status == "holds"  # unverified, the search is fooled
    for result in (run(path), run(path, check_determinism=True)):
        assert result.status == "contract breach" and result.exit_code == 4
        assert "node f, handler tick (@handler)" in result.breach
        assert "self.calls" in result.breach and "fix:" in result.breach
        assert result.trace is None


def test_check_determinism_passes_deterministic_models(tmp_path):
    for name, nodes in [("pp", PING_PONG), ("pick", [node("p", "Picker", second=[0, 100])])]:
        path = scenario(tmp_path, nodes, name=name)
        assert counts(run(path, check_determinism=True)) == counts(run(path)) == \
            counts(run(path, verify=False))
    # Sloppy keeps a counter outside self.state and never reads it: still a breach.
    sloppy = run(scenario(tmp_path, [node("s", "Sloppy")], name="sloppy"))
    assert sloppy.exit_code == 4 and "self.hits" in sloppy.breach


@pytest.mark.parametrize(("check", "match"), [
    ({"faults": {"drop": ["/nowhere"]}}, r"check.faults.drop: '/nowhere' is not a topic"),
    ({"faults": {"duplicate": ["/add_two"]}}, r"services cannot be duplicated"),
    ({"faults": {"crash": {"nodes": []}}}, r"check.faults.crash.nodes: name at least one"),
    ({"faults": {"crash": {"nodes": ["ghost"]}}}, r"'ghost' is not a node"),
    ({"faults": {"crash": {"nodes": ["client"], "max": 0}}}, r"crash.max: expected a number"),
    ({"faults": {"explode": True}}, r"check.faults.explode: unknown key"),
    ({"latency": {"/nowhere": [0, 1]}}, r"check.latency./nowhere"),
    ({"deadline_ms": -1}, r"check.deadline_ms: expected milliseconds"),
    ({"queue_bound": {"nobody": 3}}, r"check.queue_bound.nobody"),
    ({"queue_bound": 0}, r"check.queue_bound: expected a number of pending events"),
])
def test_bad_settings_are_scenario_errors(tmp_path, check, match):
    nodes = [node("client", "Client"), node("adder", "Adder")]
    path = scenario(tmp_path, nodes, name="bad", **check)
    with pytest.raises(ScenarioError, match=match):
        System(load(path), properties=PropertySet.from_scenario(load(path)))


def test_invariant_may_use_comprehensions_over_node_states(tmp_path):
    # Generator expressions and comprehensions see node names (they are nested scopes, so
    # the names must be globals of the evaluation, and must be found in nested code).
    ok = [{"name": "gen", "kind": "invariant",
           "expr": "all(n <= 3 for n in (ping.sent, pong.received))"}]
    assert run(scenario(tmp_path, PING_PONG, name="gen_ok", properties=ok)).status == "holds"
    bad = [{"name": "gen", "kind": "invariant",
            "expr": "sum([x for x in (ping.sent, pong.received)]) < 3"}]
    result = run(scenario(tmp_path, PING_PONG, name="gen_bad", properties=bad))
    assert result.status == "violated" and result.violation.property == "gen"
    assert replay_confirms(result)
