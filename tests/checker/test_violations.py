"""Counterexamples: races, deadlocks, livelocks, deadlines, failures; each trace replays."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest

from tests.checker.helpers import counts, node, replay_confirms, run, scenario, steps
from twinfleet.checker import NondeterminismError, PropertySet, System, replay
from twinfleet.checker.driver import load

pytestmark = pytest.mark.timeout(30)

DOOR = [node("opener", "Opener"), node("locker", "Locker"), node("door", "Door")]


@pytest.mark.parametrize(("semantics", "ops", "senders"), [
    # Pending at t=0: unlock, open (opener, sent in that order) and lock (locker). Under
    # ros only unlock, lock, open opens a locked door; BFS finds it at depth 3.
    ("ros", ["unlock", "lock", "open"], ["opener", "locker", "opener"]),
    # Under rebeca the opener's two messages are unordered alternatives (R2/R5), so
    # lock, open (open overtaking unlock) is a shorter counterexample: depth 2.
    ("rebeca", ["lock", "open"], ["locker", "opener"]),
])
def test_race_found_with_shortest_trace(tmp_path, semantics, ops, senders):
    result = run(scenario(tmp_path, DOOR, semantics=semantics))
    assert result.status == "violated"
    assert result.violation.property == "no_failure"
    assert "opened while locked" in result.violation.message
    assert steps(result) == [("door", "on_cmd", ())] * len(ops)
    assert [s["args"] for s in result.trace["steps"]] == [f"Cmd(op={op!r})" for op in ops]
    assert [s["sender"] for s in result.trace["steps"]] == senders
    assert result.trace["steps"][-1]["failure"]["handler"] == "on_cmd"
    assert replay_confirms(result)


def test_race_removed_holds(tmp_path):
    # unlock_open is one message: 0{uo,l} -> F,1{l} -> T,1{}; 0 -> T,0{uo} -> F,1{}.
    # 5 states, 4 transitions.
    nodes = [node("opener", "Opener", atomic=True), node("locker", "Locker"),
             node("door", "Door")]
    result = run(scenario(tmp_path, nodes))
    assert result.status == "holds"
    assert counts(result) == (5, 4, 5)
    assert result.trace is None


def test_dfs_and_random_also_find_the_race(tmp_path):
    path = scenario(tmp_path, DOOR)
    dfs = run(path, search="dfs")
    assert dfs.status == "violated"
    assert replay_confirms(dfs)
    walk = run(path, search="random", walks=50, seed=3)
    assert walk.status == "violated"
    assert len(steps(walk)) == 3
    assert replay_confirms(walk)


GOAL = "a.stage == 'done' and b.stage == 'done'"


def test_deadlock_found(tmp_path):
    # Both prepare at t=5 and wait for the other's go: S0 -A.prepare-> S1 -B.prepare-> S3 {}
    # with the goal false. Shortest trace: 2 steps, shape "terminal".
    nodes = [node("a", "WaiterA", inbox="/go_a", outbox="/go_b"),
             node("b", "WaiterB", inbox="/go_b", outbox="/go_a")]
    path = scenario(tmp_path, nodes, properties=[
        {"name": "no_deadlock", "kind": "deadlock", "expr": GOAL}])
    result = run(path)
    assert result.status == "violated"
    assert result.violation.property == "no_deadlock"
    assert result.violation.shape == "terminal"
    assert steps(result) == [("a", "prepare", ()), ("b", "prepare", ())]
    assert result.trace["steps"][-1]["pending"] == 0
    assert result.trace["steps"][-1]["time"] == 5
    assert replay_confirms(result)


def test_no_deadlock_when_one_goes_first_but_quiescent(tmp_path):
    # a sends first. S0 {A.prep, B.prep} -> S1 (A waiting){B.prep, go_b} | S2 (B waiting)
    # {A.prep}; S1 -> S3 (both waiting){go_b} | S4 (B done){B.prep, go_a}; S2 -> S3;
    # S3 -> S5 (B done){go_a}; S4 -> S5 | S6 (both done){B.prep}; S5 -> S7 {}; S6 -> S7.
    # 8 states; transitions 2+2+1+1+2+1+1 = 10.
    nodes = [node("a", "WaiterA", inbox="/go_a", outbox="/go_b", first=True),
             node("b", "WaiterB", inbox="/go_b", outbox="/go_a")]
    props = [{"name": "no_deadlock", "kind": "deadlock", "expr": GOAL},
             {"name": "finishes", "kind": "eventually", "expr": GOAL}]
    result = run(scenario(tmp_path, nodes, properties=props))
    assert result.status == "holds"
    assert counts(result) == (8, 10, 11)
    # RMC's deadlock (nothing pending at all) is still reached: S7, after 4 steps.
    props.append({"name": "never_quiet", "kind": "quiescence"})
    result = run(scenario(tmp_path, nodes, properties=props, name="q"))
    assert result.status == "violated"
    assert result.violation.property == "never_quiet"
    assert len(steps(result)) == 4
    assert replay_confirms(result)


def test_eventually_violated_by_terminal_path(tmp_path):
    nodes = [node("a", "WaiterA", inbox="/go_a", outbox="/go_b"),
             node("b", "WaiterB", inbox="/go_b", outbox="/go_a")]
    path = scenario(tmp_path, nodes, properties=[
        {"name": "finishes", "kind": "eventually", "expr": GOAL}])
    result = run(path)
    assert result.status == "violated"
    assert result.violation.shape == "terminal"
    assert result.trace["cycle_start"] is None
    assert len(steps(result)) == 2
    assert replay_confirms(result)


def test_livelock_found_as_lasso(tmp_path):
    # S0 {serve@5} -> S1 served {ball@5} -> S2 {send_back@15} -> S3 {back@15}
    # -> {ball@15} = S1 shifted by 10 ms. 4 states, 4 transitions; the ball goes round
    # for ever and nobody scores: a lasso whose cycle starts at world 1.
    nodes = [node("server", "BallServer"), node("returner", "BallReturner")]
    path = scenario(tmp_path, nodes, properties=[
        {"name": "someone_scores", "kind": "eventually", "expr": "server.scored"}])
    result = run(path)
    assert result.status == "violated"
    assert result.violation.shape == "lasso"
    assert counts(result)[:2] == (4, 4)
    assert result.trace["cycle_start"] == 1
    assert steps(result) == [("server", "serve", ()), ("returner", "on_ball", ()),
                             ("returner", "send_back", ()), ("server", "on_back", ())]
    assert result.trace["steps"][-1]["digest"] == result.trace["steps"][0]["digest"]
    assert replay_confirms(result)
    # "served" does become true on every path: holds.
    path = scenario(tmp_path, nodes, name="served", properties=[
        {"name": "serves", "kind": "eventually", "expr": "server.served"}])
    assert run(path).status == "holds"


def test_within_deadline(tmp_path):
    # count reaches 3 at t=300. Within 250: at t=200 count=2 and the next event is at
    # 300 > 250: violated after 2 ticks.
    entries = [node("c", "Counter", modulo=0, cap=5)]
    late = scenario(tmp_path, entries, name="late", properties=[
        {"name": "three_soon", "kind": "within", "expr": "c.count >= 3", "within_ms": 250}])
    result = run(late)
    assert result.status == "violated"
    assert len(steps(result)) == 2
    assert replay_confirms(result)
    # Within 300 it holds. c0 c1 c2 carry the pending monitor (and absolute time), then
    # c3 c4 c5 and c5 again: 6 states, 6 transitions.
    ok = scenario(tmp_path, entries, name="ok", properties=[
        {"name": "three_soon", "kind": "within", "expr": "c.count >= 3", "within_ms": 300}])
    result = run(ok)
    assert result.status == "holds"
    assert counts(result) == (6, 6, 7)


def test_invariant_violation_and_exception(tmp_path):
    path = scenario(tmp_path, [node("c", "Counter", modulo=0)], properties=[
        {"name": "small", "kind": "invariant", "expr": "c.count < 4"}])
    result = run(path)
    assert result.violation.property == "small"
    assert len(steps(result)) == 4
    assert result.trace["steps"][-1]["changed"] == {"c": {"count": 4}}
    assert replay_confirms(result)
    crash = run(scenario(tmp_path, [node("x", "Crasher")], name="crash"))
    assert crash.status == "violated"
    assert "RuntimeError: boom" in crash.violation.message
    assert "boom" in crash.trace["steps"][-1]["failure"]["traceback"]
    assert replay_confirms(crash)


def test_debug_state_names_node_and_handler(tmp_path):
    path = scenario(tmp_path, [node("sloppy", "Sloppy")])
    assert run(path, verify=False).status == "holds"
    for result in (run(path, debug_state=True, verify=False), run(path)):
        assert result.status == "contract breach" and result.exit_code == 4
        assert "(state outside self.state) in node sloppy, handler bump" in result.breach
        assert "hits" in result.breach


def test_a_declared_pure_memo_is_not_state_and_a_magic_attribute_declares_nothing(tmp_path):
    declared = scenario(tmp_path, [node("m", "Memoising")], name="declared")
    assert run(declared, debug_state=True).status == "holds"
    magic = scenario(tmp_path, [node("m", "Memoising", declared=False)], name="magic")
    result = run(magic, debug_state=True)
    assert result.status == "contract breach" and result.exit_code == 4
    assert "node m, handler bump" in result.breach and "memo" in result.breach


def test_replay_detects_divergence(tmp_path):
    result = run(scenario(tmp_path, DOOR))
    trace = copy.deepcopy(result.trace)
    trace["steps"][1]["digest"] = "00" * 16
    scen = load(trace["scenario"])
    props = PropertySet.from_scenario(scen)
    with pytest.raises(NondeterminismError, match=r"step 2 \(door.on_cmd\)"):
        replay(System(scen, properties=props), trace, props)
    # The written file is the same trace.
    on_disk = json.loads(Path(result.trace_path).read_text())
    assert on_disk["format"] == "twinfleet-trace/1"
    assert on_disk["steps"] == result.trace["steps"]


def test_random_walk_finds_the_livelock(tmp_path):
    nodes = [node("server", "BallServer"), node("returner", "BallReturner")]
    path = scenario(tmp_path, nodes, properties=[
        {"name": "someone_scores", "kind": "eventually", "expr": "server.scored"}])
    result = run(path, search="random", walks=1, seed=0)
    assert result.status == "violated"
    assert result.violation.shape == "lasso"
    assert result.trace["cycle_start"] == 1
    assert len(steps(result)) == 4
    assert replay_confirms(result)
