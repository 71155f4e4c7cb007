"""The partial-order reduction (docs/reduction.md): exact reduced counts of hand-counted models,
where it turns itself off and how the result says which reduction ran.

Notation as in tests/checker/test_counts.py: a world is "what is done {pending}".
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.checker.helpers import counts, node, replay_confirms, run, scenario
from tests.checker.tpc import tpc_scenario
from twinfleet.checker.driver import CheckOptions, check, load
from twinfleet.checker.properties import PropertySet
from twinfleet.checker.publications import Publications
from twinfleet.checker.reduction import (
    ASIDE_NONE_WORLDS,
    ASIDE_SHARE,
    ASIDE_WORLDS,
    Reduction,
    describe,
)
from twinfleet.checker.search import Search
from twinfleet.checker.system import System
from twinfleet.cli import main

pytestmark = pytest.mark.timeout(60)

SUM_OK = {"name": "total_ok", "kind": "invariant", "expr": "sum.total in (0, 1, 2, 3, 4, 5, 6, 7)"}


@pytest.mark.parametrize(("reduction", "expected"), [
    # Three independent zero-delay flag timers at t=0. Unreduced: every subset of raised
    # flags is a world, 8 states; a world with k flags pending has k transitions, 12.
    ("none", (8, 12, 13)),
    # Reduced: each world's persistent set is the lowest node's flag alone (no node sends
    # anything, so nothing can disturb it): {f1,f2,f3} -> {f2,f3} -> {f3} -> {}: 4 states,
    # 3 transitions.
    ("por", (4, 3, 4)),
])
def test_independent_flags(tmp_path, reduction, expected):
    path = scenario(tmp_path, [node(f"f{i}", "Flagger") for i in (1, 2, 3)])
    result = run(path, reduction=reduction)
    assert result.status == "holds"
    assert counts(result) == expected
    assert result.reduction.split(" ")[0] == reduction


@pytest.mark.parametrize(("reduction", "expected"), [
    # Two flags f1, f2 and a shared sink `sum` receiving 1, 2 (FIFO, from `two`) and 4.
    # Unreduced: 4 flag combinations x the sink's 6 worlds (see test_counts) = 24 states;
    # transitions: per flag combination the sink's 7, plus 2 x 6 + 2 x 6 flag steps = 52.
    ("none", (24, 52, 53)),
    # Reduced: f1's flag, then f2's, each alone ({f1,f2,1,2,4} -> {f2,1,2,4} -> {1,2,4});
    # then only the sink has enabled events, which are all dependent (one node): its 6
    # worlds and 7 transitions in full. 2 + 6 = 8 states, 2 + 7 = 9 transitions. The
    # invariant reads the sink only, so the flags are invisible to it.
    ("por", (8, 9, 10)),
])
def test_flags_and_a_shared_sink(tmp_path, reduction, expected):
    path = scenario(tmp_path, [node("f1", "Flagger"), node("f2", "Flagger"),
                               node("two", "TwoSender"), node("four", "FourSender"),
                               node("sum", "Summer")], properties=[SUM_OK])
    result = run(path, reduction=reduction)
    assert result.status == "holds"
    assert counts(result) == expected


def test_default_is_por_under_ros_and_none_under_rebeca(tmp_path):
    nodes = [node("f1", "Flagger"), node("f2", "Flagger")]
    ros = run(scenario(tmp_path, nodes), reduction=None)
    rebeca = run(scenario(tmp_path, nodes, semantics="rebeca"), reduction=None)
    assert ros.reduction.startswith("por (")
    assert rebeca.reduction == "none (default under rebeca)"
    assert counts(rebeca) == (4, 4, 5)
    forced = run(scenario(tmp_path, nodes, semantics="rebeca"), reduction="por")
    assert forced.reduction.startswith("por (") and counts(forced) == (3, 2, 3)


@pytest.mark.parametrize(("extra", "why"), [
    ({"check": {"queue_bound": 5}}, "none (check.queue_bound reads the pending counts)"),
    ({"properties": [{"name": "soon", "kind": "invariant", "expr": "now < 10 or f1.done"}]},
     "none (a property reads now)"),
    ({"search": "random"}, "none (random walks pick among all actions)"),
])
def test_turns_itself_off_and_says_why(tmp_path, extra, why):
    nodes = [node("f1", "Flagger"), node("f2", "Flagger")]
    path = scenario(tmp_path, nodes, properties=extra.get("properties"),
                    **extra.get("check", {}))
    result = run(path, search=extra.get("search"), reduction=None)
    assert result.reduction == why
    assert why in result.summary()
    assert result.to_json()["reduction"] == why


def test_rebeca_node_priorities_turn_it_off(tmp_path):
    path = scenario(tmp_path, [node("f1", "Flagger", 1), node("f2", "Flagger", 2)],
                    semantics="rebeca")
    result = run(path, reduction="por")
    assert result.reduction == "none (node-instance priorities under rebeca (Rule 4))"
    assert counts(result) == (3, 2, 3)


def test_reduced_counterexample_replays(tmp_path):
    # A violation behind independent flags: the reduced trace is an ordinary path.
    bad = {"name": "small", "kind": "invariant", "expr": "sum.total < 3"}
    path = scenario(tmp_path, [node("f1", "Flagger"), node("f2", "Flagger"),
                               node("two", "TwoSender"), node("four", "FourSender"),
                               node("sum", "Summer")], properties=[bad])
    result = run(path, reduction="por")
    assert result.status == "violated"
    assert replay_confirms(result)


def test_cli_flag_and_json(tmp_path, capsys):
    path = scenario(tmp_path, [node(f"f{i}", "Flagger") for i in (1, 2, 3)])
    code = main(["check", str(path), "--json", "--reduction", "none"])
    doc = json.loads(capsys.readouterr().out)
    assert code == 0 and doc["reduction"] == "none" and doc["states"] == 8
    # por by default, but 8 worlds are far fewer than the reduction waits for: unreduced
    code = main(["check", str(path), "--json"])
    doc = json.loads(capsys.readouterr().out)
    assert doc["reduction"] == ("none (por starts once a search stored 1,000 worlds: a "
                                "smaller one costs more to reduce than to search; this one "
                                "stored fewer)")
    assert doc["states"] == 8 and doc["reduction_statistics"]["reduced"] == 0
    reduced = run(path, reduction="por")  # from the first world
    assert reduced.reduction.startswith("por") and reduced.statistics.states == 4
    # S0 and S1 are reduced; S2 (one event left) and the terminal S3 count as full
    assert reduced.reduction_statistics is not None
    assert (reduced.reduction_statistics["reduced"], reduced.reduction_statistics["full"]) == (2, 2)


def test_unknown_reduction_is_bad_input(tmp_path):
    path = scenario(tmp_path, [node("f1", "Flagger")])
    with pytest.raises(ValueError, match="unknown reduction 'fast'"):
        check(path, CheckOptions(reduction="fast"))


@pytest.mark.parametrize(("reduction", "expected"), [
    # Ping-pong (3 rounds: 7 worlds in a chain, see test_counts) beside an independent flag.
    # Unreduced: each chain world with and without the flag, 14 states; 6 chain steps twice
    # and 7 flag steps, 19 transitions.
    ("none", (14, 19, 20)),
    # Reduced: the chain first (pong's and ping's events alone: nothing else can send to
    # them at the instant), the flag last: 8 states, 7 transitions. The send relation is
    # learned on the way: pong's on_ping sends to ping (restart 1); the walk on from the
    # level where that was seen (`Reduction.walk_on`) meets ping's on_pong sending to pong
    # too, so the second search knows both from its start (without the walk, a second
    # restart learned it).
    ("por", (8, 7, 8)),
])
def test_send_relation_is_learned_with_restarts(tmp_path, reduction, expected):
    path = scenario(tmp_path, [node("ping", "Ping", rounds=3), node("pong", "Pong"),
                               node("f", "Flagger")])
    result = run(path, reduction=reduction)
    assert counts(result) == expected
    if reduction == "por":
        assert result.reduction_statistics is not None
        assert result.reduction_statistics["restarts"] == 1
        assert "1 restart;" in result.reduction
        # the rate counts the last attempt's transitions over the time since it began
        s = result.statistics
        assert s.attempt_s is not None and 0 < s.attempt_s <= s.elapsed_s
        assert s.attempt_transitions_per_s == pytest.approx(s.transitions / s.attempt_s)
        assert "since the search last started again" in result.summary()
    else:
        assert result.statistics.attempt_s is None
        assert "since the search last started again" not in result.summary()


REPORTERS = [node(f"r{v}", "Reporter", value=v) for v in (1, 2, 3)]
TOTAL_OK = {"name": "total_ok", "kind": "invariant", "expr": "tally.total <= 321"}


@pytest.mark.parametrize(("reduction", "expected"), [
    # Three reports reach `tally` at t=0 from three senders. Unreduced: every subset of
    # handled reports is a world (the total is the subset's sum), 8 states, 12 transitions.
    ("none", (8, 12, 13)),
    # Reduced: the handler is declared commutes=True, so the tally gives one report at a
    # time: {1,2,3} -> {2,3} -> {3} -> {}, 4 states, 3 transitions. The pairs checked in
    # both orders: (1,2), (1,3) in the first world, (2,3) in the second.
    ("por", (4, 3, 4)),
])
def test_declared_commuting_messages_take_one_order(tmp_path, reduction, expected):
    path = scenario(tmp_path, [*REPORTERS, node("tally", "Tally")], properties=[TOTAL_OK])
    result = run(path, reduction=reduction)
    assert result.status == "holds"
    assert counts(result) == expected
    if reduction == "por":
        stats = result.reduction_statistics
        assert stats is not None
        assert (stats["commuted"], stats["pairs"], stats["refuted"]) == (2, 3, 0)
        assert "(tally.on_report), 3 pairs checked in both orders, 0 did not commute" \
            in result.reduction


def test_a_false_commutes_declaration_is_caught_by_the_pair_check(tmp_path):
    # Digits writes 123 or 321 or ...: every pair differs in its two orders, so every world
    # with two reports waiting is expanded fully and the counts are the unreduced ones:
    # every ordered sequence of handled reports is a world, 1 + 3 + 6 + 6 = 16 states and
    # 3 + 6 + 6 = 15 transitions.
    path = scenario(tmp_path, [*REPORTERS, node("tally", "Digits")], properties=[TOTAL_OK])
    full = run(path, reduction="none")
    reduced = run(path, reduction="por")
    assert counts(reduced) == counts(full) == (16, 15, 16)
    stats = reduced.reduction_statistics
    assert stats is not None and stats["commuted"] == 0
    # the first pair of each world with 2+ reports waiting fails: 1 + 3 worlds
    assert stats["pairs"] == stats["refuted"] == 4


ALL_FLAGS = {"name": "all_flags", "kind": "eventually", "expr": "f1.done and f2.done and f3.done"}


@pytest.mark.parametrize(("reduction", "expected"), [
    ("none", (8, 12, 13)),
    # Each flag makes an atom of the goal rise, which no flag ever lowers: the flags are
    # taken one at a time as without the goal (4 states, 3 transitions). Without the rising
    # rule every flag would be visible and the persistent set would hold all three.
    ("por", (4, 3, 4)),
])
def test_rising_goal_atoms_are_not_visible(tmp_path, reduction, expected):
    path = scenario(tmp_path, [node(f"f{i}", "Flagger") for i in (1, 2, 3)],
                    properties=[ALL_FLAGS])
    result = run(path, reduction=reduction)
    assert result.status == "holds"
    assert counts(result) == expected


def test_a_falling_goal_atom_turns_the_rising_rule_off(tmp_path):
    goal = {"name": "both", "kind": "eventually", "expr": "f1.done and f2.done"}
    path = scenario(tmp_path, [node("f1", "Flagger"), node("f2", "Flipper")], properties=[goal])
    full = run(path, reduction="none")
    reduced = run(path, reduction="por")
    assert reduced.status == full.status == "holds"
    assert "goals not rising: f2.lower makes an atom of `f1.done and f2.done` false" \
        in reduced.reduction
    assert reduced.reduction_statistics is not None
    assert reduced.reduction_statistics["restarts"] >= 1


@pytest.mark.parametrize("search", ["bfs", "dfs"])
def test_a_reduction_that_does_not_pay_steps_aside(tmp_path, search):
    # A two-phase commit with 0-2 ms of latency (tests/checker/tpc.py, 438 worlds): every
    # message crosses between two nodes and the property reads both participants, so few
    # worlds have a persistent set smaller than everything (none of the first 114 in a BFS,
    # 34 of the first 300 in a DFS). The reduction steps aside, the search runs unreduced
    # and finds exactly the unreduced graph, and the summary says why.
    protocol = tpc_scenario(tmp_path)
    full = check(protocol, CheckOptions(reduction="none", search=search))
    reduced = check(protocol, CheckOptions(reduction="por", reduce_from=0, search=search))
    assert full.status == reduced.status == "holds"
    assert counts(reduced) == counts(full)
    assert reduced.reduction.startswith("none (por stepped aside: ")
    assert reduced.reduction.endswith("worlds reduced, under 20%; the search ran unreduced)")
    stats = reduced.reduction_statistics
    assert stats is not None and stats["aside"] >= ASIDE_NONE_WORLDS
    assert stats["reduced"] < ASIDE_SHARE * stats["aside"]
    assert stats["reduced"] == 0 or stats["aside"] >= ASIDE_WORLDS


TWO_PHASE = Path(__file__).resolve().parents[1] / "data" / "two_phase" / "two_phase_small.yaml"


@pytest.mark.parametrize("search", ["bfs", "dfs"])
def test_a_step_aside_with_nothing_reduced_goes_on_in_place(monkeypatch, search):
    # The small two-phase commit of tests/data (2,843 worlds). Under BFS none of the first
    # 114 worlds was reduced: they were expanded fully in the unreduced order, so the
    # search keeps them (160 stored) and goes on unreduced instead of searching them again
    # (one pass fewer). Under DFS some were reduced (16 of 300): that search starts again.
    passes = []
    monkeypatch.setattr(Search, "_explore", lambda self, f=Search._explore: (
        passes.append(len(self.store)), f(self))[1])
    reduced = check(TWO_PHASE, CheckOptions(reduction="por", reduce_from=0, search=search))
    stats = reduced.reduction_statistics
    assert stats is not None and "stepped aside" in reduced.reduction
    assert counts(reduced) == counts(check(TWO_PHASE, CheckOptions(reduction="none",
                                                                     search=search)))
    passes_of_por = len(passes) - 1  # the unreduced check above made one
    assert passes_of_por == stats["restarts"] + (search == "dfs") + 1
    assert (stats["reduced"] == 0) is (search == "bfs")


@pytest.mark.parametrize(("reduced", "full", "aside"), [
    (0, ASIDE_NONE_WORLDS - 1, False),  # too few worlds to judge
    (0, ASIDE_NONE_WORLDS, True),  # none reduced: judged sooner
    (1, ASIDE_WORLDS - 2, False),  # some reduced: too few worlds to judge
    (199, 801, True),  # under a fifth reduced
    (200, 800, False),
    (4_043, 1_473, False),  # C1a's final search
])
def test_steps_aside_only_when_few_worlds_are_reduced(tmp_path, reduced, full, aside):
    path = scenario(tmp_path, [node("f1", "Flagger")])
    scenario_ = load(str(path))
    props = PropertySet.from_scenario(scenario_)
    reduction = Reduction(System(scenario_, properties=props), props)
    reduction.stats.reduced, reduction.stats.full = reduced, full
    assert reduction.steps_aside() is aside
    assert (reduction.aside is not None) is aside
    assert describe(reduction, "por").startswith("none (por stepped aside") is aside


def test_restarts_run_the_handlers_of_the_first_levels_from_the_cache(monkeypatch):
    # C2c's reduced search restarts 18 times, each from time 0. Its handler outcomes stay
    # cached across restarts (the search does not forget those older than its frontier
    # while it reduces), so it runs handlers about as often as a search that knew the send
    # relation from the start (measured: 1,984 runs against 1,552; when the outcomes older
    # than the frontier were forgotten, 4,054 against 2,566).
    path = Path(__file__).resolve().parents[2] / "twinfleet" / "launch" / "c2c.yaml"
    monkeypatch.setattr(Reduction, "walk_on", lambda *_: None)  # the restarts of old

    def search(learned: tuple[object, ...] | None) -> tuple[int, Reduction]:
        scenario_ = load(str(path))
        props = PropertySet.from_scenario(scenario_)
        system = System(scenario_, properties=props)
        reduction = Reduction(system, props)
        if learned is not None:
            reduction.relearn(learned)
        Search(system, props, handle_sigint=False, reduction=reduction).run("bfs")
        return system.runner.handler_runs, reduction

    restarting, reduction = search(None)
    knowing, again = search(reduction.learned_state())
    assert reduction.stats.restarts > 10 and again.stats.restarts == 0
    assert restarting < 1.4 * knowing


def test_a_restart_walks_on_and_learns_the_sends_of_deeper_levels_at_once(monkeypatch):
    # headon, reduced: a BFS learned its sends level by level and restarted 11 times, 5 of
    # them after its first 100 worlds (9 since a robot's sends count for its twin too). Walking on from the level where a restart comes
    # learns what deeper levels send, for the same graph and trace.
    path = Path(__file__).resolve().parents[2] / "twinfleet" / "launch" / "headon.yaml"
    walking = check(path, CheckOptions(reduction="por", reduce_from=0))
    monkeypatch.setattr(Reduction, "walk_on", lambda *_: None)
    level_by_level = check(path, CheckOptions(reduction="por", reduce_from=0))
    assert walking.status == level_by_level.status == "violated"
    assert counts(walking) == counts(level_by_level)
    assert walking.trace == level_by_level.trace
    assert walking.reduction_statistics is not None
    assert level_by_level.reduction_statistics is not None
    assert walking.reduction_statistics["restarts"] <= 3
    assert level_by_level.reduction_statistics["restarts"] >= 8


def test_a_checkpoint_keeps_the_step_aside(tmp_path):
    # Stopped after the reduction stepped aside, the search resumes unreduced and ends with
    # the unreduced counts, saying so.
    protocol = tpc_scenario(tmp_path)  # steps aside after 114 worlds expanded, 160 found
    saved = str(tmp_path / "search.ckpt")
    stopped = check(protocol, CheckOptions(max_states=425, checkpoint=saved, reduce_from=0))
    assert stopped.status == "unknown" and "stepped aside" in stopped.reduction
    resumed = check(protocol, CheckOptions(resume=saved))
    assert resumed.status == "holds" and "stepped aside" in resumed.reduction
    assert counts(resumed) == counts(check(protocol, CheckOptions(reduction="none")))


STATION = Path(__file__).resolve().parents[1] / "data" / "station" / "station.yaml"


def test_a_send_counts_for_the_other_nodes_of_its_class():
    # The station's two askers (one class): the first search level sees asker a's answer
    # handler publish /plugged to the station; asker b's is learned with it, not at a restart
    # when b first wins the station (2 restarts before, 1 now), for the same graph.
    reduced = check(STATION, CheckOptions(reduction="por", reduce_from=0))
    assert reduced.status == check(STATION, CheckOptions(reduction="none")).status
    assert reduced.statistics.states == 25
    assert reduced.reduction_statistics is not None
    assert reduced.reduction_statistics["restarts"] == 1
    scenario_ = load(str(STATION))
    system = System(scenario_, properties=PropertySet.from_scenario(scenario_))
    names = list(system.names)
    station, a, b = (names.index(n) for n in ("station", "a", "b"))
    assert system.publications.peers[a] == (b,) and system.publications.peers[station] == ()


def test_peers_get_sends_to_other_classes_only():
    relation = Publications(3, [(), (2,), (1,)])  # node 0 alone; 1 and 2 of one class
    relation._add(0, (1, "on_answer"), ("on_plugged", 0))
    relation._add(2, (1, "on_answer"), ("on_poke", 0))  # into a peer: not mirrored
    relation._add(1, (1, "tick"), ("tick", 1))  # a node's own timer: not mirrored
    assert relation.into[0] == {(1, "on_answer"): {("on_plugged", 0)},
                                (2, "on_answer"): {("on_plugged", 0)}}
    assert relation.into[2] == {(1, "on_answer"): {("on_poke", 0)}}
    assert relation.into[1] == {(1, "tick"): {("tick", 1)}}
    assert relation.out[(2, "on_answer")] == {(0, "on_plugged")}
