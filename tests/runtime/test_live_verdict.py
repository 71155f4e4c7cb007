"""The live verdict without a fleet: state reports from real node cores, judged by a
`LiveJudge`; the core's lossless-drop and stall counters; the verdict's precedence."""

from __future__ import annotations

from typing import Any

import pytest

from tests.adversarial.verdict_nodes import Counter, Flooder
from tests.runtime.hosts import Num, Shallow
from twinfleet.runtime.contract.kinds import Status
from twinfleet.runtime.contract.messages import encode
from twinfleet.runtime.core.node_core import NodeCore
from twinfleet.runtime.core.state_report import StateReport, StateReporter, decode_report
from twinfleet.runtime.core.statistics import NodeStatistics, Outside, Rejection
from twinfleet.runtime.fleet.live_verdict import LiveJudge, RunEnd, stall_floor_ms
from twinfleet.runtime.scenario.spec import NodeEntry, Scenario

pytestmark = pytest.mark.timeout(30)


def scenario(*props: dict[str, Any], fail_at: int = 0, misuse_at: int = 0) -> Scenario:
    return Scenario.build("counting", [NodeEntry("counter", Counter, {"fail_at": fail_at,
                                                                      "misuse_at": misuse_at}),
                                       NodeEntry("other", Counter)], properties=list(props))


class Fleet:
    """Node cores whose state reports go straight to a monitor (as the launcher's do)."""

    def __init__(self, sc: Scenario, **monitor: Any) -> None:
        self.judge = LiveJudge(sc, **monitor)
        self.cores = {}
        for cfg in sc.nodes:
            node = cfg.instantiate()
            core = NodeCore(node, seed=1, stall_ms=self.judge.stall_ms)
            core.observe(StateReporter(node, self._put(node.name)))
            self.cores[node.name] = core
        self.wire: list[tuple[str, bytes]] = []

    def _put(self, name: str):
        def put(payload: bytes) -> None:
            self.wire.append((name, payload))
        return put

    def run(self, until_ms: int, *, drop: int | None = None) -> None:
        """Tick every core up to `until_ms`, delivering reports (but the `drop`-th)."""
        for core in self.cores.values():
            core.start(0)
        for now in range(0, until_ms + 1, 50):
            for core in self.cores.values():
                core.release_due(now)
                while core.run_next(now) is not None:
                    pass
        for i, (name, payload) in enumerate(self.wire):
            if i != drop:
                self.judge.on_report(decode_report(name, payload))

    def verdict(self, **end: Any):
        stats = {n: NodeStatistics() for n in self.cores}  # nothing lost
        return self.judge.verdict(RunEnd(end.pop("reason", "timeout"), statistics=stats, **end))


def test_an_invariant_violated_names_the_property_the_event_and_the_states():
    fleet = Fleet(scenario({"name": "small", "kind": "invariant", "expr": "counter.count < 3"}))
    fleet.run(300)
    v = fleet.verdict()
    assert (v.status, v.property_name, v.exit_code) == (Status.VIOLATED, "small", 1)
    assert "invariant 'counter.count < 3' is false at t=150 ms" in v.summary  # fleet time: 3rd tick
    assert "after periodic → counter.tick" in v.details[0]
    assert v.details[1] == "counter: CountState(count=3)"


def test_a_handler_that_breaks_the_node_contract_is_a_breach_not_a_violation():
    fleet = Fleet(scenario({"name": "clean", "kind": "no_failure"}, misuse_at=2))
    fleet.run(200)
    v = fleet.verdict()
    assert (v.status, v.exit_code) == (Status.BREACH, 4), v
    assert v.summary.startswith("contract breach in counter.tick: ContractError: "), v.summary
    assert "; fix: register the class with @message" in v.summary
    assert not fleet.judge.violations  # the same code breaks no property: it has no verdict


def test_a_handler_failure_violates_the_scenarios_no_failure_property():
    fleet = Fleet(scenario({"name": "clean", "kind": "no_failure"}, fail_at=2))
    fleet.run(200)
    v = fleet.verdict()
    assert (v.status, v.property_name) == (Status.VIOLATED, "clean")
    assert "counter.tick: ValueError: count reached 2" in v.summary
    # rolled back, the state stays where the handler raised, so every later tick raises again
    assert fleet.judge.failures == {"counter": 3}


def judged(*props: dict[str, Any], until_ms: int = 300):
    """The verdict on `props` of a fleet ticked up to `until_ms`."""
    fleet = Fleet(scenario(*props))
    fleet.run(until_ms)
    return fleet.verdict()


@pytest.mark.parametrize(("props", "status", "said"), [
    ([{"name": "e", "kind": "eventually", "expr": "other.count >= 2"},
      {"name": "w", "kind": "within", "expr": "counter.count >= 2", "within_ms": 200}],
     Status.HOLDS, "e, w, no_failure hold"),
    ([{"name": "w", "kind": "within", "expr": "counter.count >= 5", "within_ms": 100}],
     Status.VIOLATED, "w violated: 'counter.count >= 5' did not hold within 100 ms"),
    ([{"name": "e", "kind": "eventually", "expr": "other.count > 99"}],
     Status.VIOLATED, "e violated: 'other.count > 99' never held before the run ended"),
    ([{"name": "w", "kind": "within", "expr": "counter.count > 99", "within_ms": 10_000}],
     Status.INCONCLUSIVE, "before w's within_ms 10000 had passed"),
])
def test_eventually_and_within_hold_or_fail_at_the_end(props, status, said):
    v = judged(*props)
    assert v.status == status and said in v.summary, v


def test_a_lost_state_report_makes_the_verdict_inconclusive():
    fleet = Fleet(scenario({"name": "ok", "kind": "invariant", "expr": "counter.count >= 0"}))
    fleet.run(300, drop=3)
    v = fleet.verdict()
    assert (v.status, v.exit_code) == (Status.INCONCLUSIVE, 3)
    assert "lost 1 state reports" in v.summary


# One case per counter the verdict judges: each alone makes a run inconclusive.
LOSSY: list[tuple[NodeStatistics, str]] = [
    (NodeStatistics(rejected={Rejection.FORGED: 10}),
     "counter rejected 10 samples (rejected_forged)"),
    (NodeStatistics(rejected={Rejection.INVALID: 2}),
     "counter rejected 2 samples (rejected_invalid)"),
    (NodeStatistics(rejected={Rejection.OVERSIZE: 1}),
     "counter rejected 1 samples (rejected_oversize)"),
    (NodeStatistics(rejected={Rejection.WRONG_TYPE: 4}),
     "counter rejected 4 samples (rejected_wrong_type)"),
    (NodeStatistics(rejected={Rejection.REPLAYED: 3}),
     "counter rejected 3 samples (rejected_replayed)"),
    (NodeStatistics(rejected={Rejection.RECORDED: 5}),
     "counter rejected 5 samples (rejected_recorded)"),
    (NodeStatistics(dropped_overflow=30101), "dropped 30101 samples at the transport hand-off"),
    (NodeStatistics(dropped_lossless=48), "RELIABLE (lossless) subscription"),
    (NodeStatistics(gaps=2), "lost 2 samples on reliable topics"),
    (NodeStatistics(stalls=3, max_lateness_ms=5012, stall_threshold_ms=200),
     "fell behind its timers by up to 5012 ms (3 timers later than its stall threshold of 200"),
]


@pytest.mark.parametrize(("stats", "said"), LOSSY)
def test_final_statistics_that_show_lost_input_make_it_inconclusive(stats, said):
    fleet = Fleet(scenario({"name": "small", "kind": "invariant", "expr": "counter.count < 3"}))
    fleet.run(300)
    v = fleet.judge.verdict(RunEnd("timeout", statistics={"counter": stats,
                                                            "other": NodeStatistics()}))
    assert v.status == Status.INCONCLUSIVE and said in v.summary, v
    assert any("seen, but not conclusive: small violated" in d for d in v.details)


def test_every_rejection_reason_is_judged():
    """A reason added to `Rejection` is judged without a change to the verdict."""
    judged = {said.rsplit("(", 1)[-1].rstrip(")") for stats, said in LOSSY if "rejected" in said}
    assert judged == {reason.counter for reason in Rejection}


def test_recorded_input_played_into_the_fleet_is_said_first():
    fleet = Fleet(scenario({"name": "ok", "kind": "invariant", "expr": "counter.count >= 0"}))
    fleet.run(300)
    v = fleet.judge.verdict(RunEnd("timeout", statistics={"counter": NodeStatistics(played=7),
                                                            "other": NodeStatistics()}))
    assert v.status == Status.HOLDS, v
    assert v.details[0] == ("took external input (from outside the fleet; the checked model "
                            "has no such input): counter: 7 recorded samples from twinfleet "
                            "play --into-fleet")


def test_statistics_that_count_no_loss_leave_the_verdict_alone():
    fleet = Fleet(scenario({"name": "ok", "kind": "invariant", "expr": "counter.count >= 0"}))
    fleet.run(300)
    busy = NodeStatistics(received=40, handled=40, published=12, dropped_keep_last=3,
                          dropped_best_effort=2, sequence_jumps=1, max_lateness_ms=30,
                          stall_threshold_ms=200)
    v = fleet.judge.verdict(RunEnd("timeout", statistics={"counter": busy, "other": busy}))
    assert v.status == Status.HOLDS, v


def test_a_run_that_took_external_input_says_so_and_is_judged_as_any_other():
    fleet = Fleet(scenario({"name": "ok", "kind": "invariant", "expr": "counter.count >= 0"}))
    fleet.run(300)
    plain = fleet.judge.verdict(RunEnd("timeout", statistics={"counter": NodeStatistics(),
                                                              "other": NodeStatistics()}))
    assert not any("external input" in d for d in plain.details)
    fed = NodeStatistics(received=3, handled=3, external_input=2)
    v = fleet.judge.verdict(RunEnd("timeout", statistics={"counter": fed,
                                                          "other": NodeStatistics()}))
    assert v.status == Status.HOLDS and v.summary == plain.summary
    assert v.details[0].startswith("took external input") and \
        "counter: 2 samples from the ROS 2 bridge" in v.details[0]


def test_every_source_of_outside_input_is_named_in_one_line_with_its_topics():
    fleet = Fleet(scenario({"name": "ok", "kind": "invariant", "expr": "counter.count >= 0"}))
    fleet.run(300)
    fed = NodeStatistics(external_input=1, played=3, outside_input=(
        (Outside.BRIDGE, "/goal", 1), (Outside.OPERATOR, "/chatter", 2),
        (Outside.OPERATOR, "/add", 1)))
    v = fleet.judge.verdict(RunEnd("timeout", statistics={"counter": fed,
                                                          "other": NodeStatistics()}))
    assert v.status == Status.HOLDS, v
    assert v.details[0] == (
        "took external input (from outside the fleet; the checked model has no such input): "
        "counter: 1 on /goal from the ROS 2 bridge, 2 on /chatter from an operator's command "
        "(topic pub, service call), 1 on /add from an operator's command (topic pub, service "
        "call), 3 recorded samples from twinfleet play --into-fleet")


def test_statistics_the_launcher_could_not_read_make_it_inconclusive():
    fleet = Fleet(scenario({"name": "ok", "kind": "invariant", "expr": "counter.count >= 0"}))
    fleet.run(100)
    v = fleet.judge.verdict(RunEnd("timeout", statistics={"other": NodeStatistics()},
                                     running=("counter", "other"),
                                     unreadable={"counter": "unknown counters 'lost'"}))
    assert v.status == Status.INCONCLUSIVE, v
    assert "counter sent statistics the launcher cannot read (unknown counters 'lost')" in v.summary


def test_a_running_node_that_does_not_answer_for_its_statistics_is_inconclusive():
    fleet = Fleet(scenario({"name": "ok", "kind": "invariant", "expr": "counter.count >= 0"}))
    fleet.run(100)
    v = fleet.judge.verdict(RunEnd("timeout", statistics={"other": NodeStatistics()},
                                     running=("counter", "other")))
    assert v.status == Status.INCONCLUSIVE and "counter did not answer" in v.summary


def test_interrupted_unless_something_was_violated_first():
    ok = Fleet(scenario({"name": "e", "kind": "eventually", "expr": "counter.count > 99"}))
    ok.run(100)
    assert ok.verdict(reason="SIGINT received", interrupted=True).status == Status.INTERRUPTED
    bad = Fleet(scenario({"name": "small", "kind": "invariant", "expr": "counter.count < 1"}))
    bad.run(100)
    assert bad.verdict(reason="SIGINT received", interrupted=True).status == Status.VIOLATED


def test_a_property_that_raises_is_a_scenario_error_and_a_slow_one_is_not_judged():
    raises = Fleet(scenario({"name": "bad", "kind": "invariant", "expr": "counter.nope > 0"}))
    raises.run(100)
    v = raises.verdict()
    assert (v.status, v.exit_code) == (Status.ERROR, 2) and "'counter.nope > 0' raised" in v.summary
    slow = Fleet(scenario({"name": "slow", "kind": "invariant",
                           "expr": "counter.count + sum(range(10**12)) > 0"}), budget_s=0.05)
    slow.run(50)
    v = slow.verdict()
    assert v.status == Status.INCONCLUSIVE and "took longer than 0.05 s" in v.summary


def test_reports_only_when_the_state_changed_or_a_handler_failed():
    fleet = Fleet(scenario({"name": "e", "kind": "eventually", "expr": "counter.count > 0"}))
    fleet.run(200)
    # ticks at 50..200 change each counter: 4 reports per node, none for unchanged states
    assert [n for n, _ in fleet.wire].count("counter") == 4
    assert fleet.judge.reads() == {"counter"}


def test_the_core_counts_lossless_drops_apart_and_stalls_against_its_threshold():
    node = Shallow("s")
    core = NodeCore(node, seed=1, stall_ms=100)
    core.start(0)
    reliable, best_effort = core.receiver("on_num"), core.receiver("on_other")
    for seq in range(1, 6):
        reliable(encode(Num(seq), stamp_ms=0, seq=seq, sender="a"), 0)
        best_effort(encode(Num(seq), stamp_ms=0, seq=seq, sender="a"), 0)
    stats = core.statistics()
    assert (stats.dropped_keep_last, stats.dropped_lossless) == (2 + 4, 2)
    counter = NodeCore(Counter("c"), seed=1, stall_ms=25)
    counter.start(0)
    counter.release_due(60)  # the tick due at 50: 10 ms late
    counter.release_due(5_000)  # the next, due at 100: 4.9 s late (a stopped process)
    stats = counter.statistics()
    assert (stats.stalls, stats.max_lateness_ms, stats.stall_threshold_ms) == (1, 4_900, 100)


def test_the_stall_threshold_is_twice_the_shortest_timer_period_above_a_wall_floor():
    assert (stall_floor_ms(), stall_floor_ms(time_scale=10)) == (100, 1000)
    every = NodeCore(Counter("c"), seed=1, stall_ms=25)  # @every(50)
    every.start(0)
    assert every.stall_threshold() == 100
    chained = NodeCore(Flooder("f"), seed=1, stall_ms=25)  # ctx.after(300), then 100
    chained.start(0)
    assert chained.stall_threshold() == 25  # no timer armed yet: the floor
    chained.run_next(0)
    assert chained.stall_threshold() == 600
    chained.release_due(300)
    chained.run_next(300)
    assert chained.stall_threshold() == 200
    assert NodeCore(Counter("c"), seed=1, stall_ms=500).stall_threshold() == 500


def test_reports_of_strangers_are_ignored_and_a_broken_state_is_inconclusive():
    fleet = Fleet(scenario({"name": "ok", "kind": "invariant", "expr": "counter.count >= 0"}))
    fleet.run(100)
    stranger = StateReport("intruder", 1, 0, "start", "x", "", "", "boom", None)
    fleet.judge.on_report(stranger)
    assert fleet.judge.strangers == 1 and fleet.verdict().status == Status.HOLDS
    broken = StateReport("other", 99, 200, "periodic", "tick", "other", "", None, b"\xc1")
    fleet.judge.on_report(broken)
    v = fleet.verdict()
    assert v.status == Status.INCONCLUSIVE
    assert "undecodable state" in " ".join([v.summary, *v.details])


def test_an_invariant_false_in_the_initial_states_is_violated_at_once():
    monitor = LiveJudge(scenario({"name": "started", "kind": "invariant",
                                    "expr": "counter.count > 0"}))
    v = monitor.verdict(RunEnd("timeout", statistics={"counter": NodeStatistics(),
                                                      "other": NodeStatistics()}))
    assert (v.status, v.property_name) == (Status.VIOLATED, "started")
    assert "false in the initial states" in v.summary and "in the initial states" in v.details[0]


def test_an_operators_refused_input_is_named_and_leaves_the_verdict_alone():
    fleet = Fleet(scenario({"name": "ok", "kind": "invariant", "expr": "counter.count >= 0"}))
    fleet.run(300)
    forced = NodeStatistics(rejected_external=2)
    v = fleet.judge.verdict(RunEnd("timeout", statistics={"counter": forced,
                                                            "other": NodeStatistics()}))
    assert v.status == Status.HOLDS, v
    assert v.details[-1] == ("external input: counter refused 2 samples an operator's "
                             "command sent (e.g. `twinfleet topic pub --force`)")


@pytest.mark.parametrize(("prop", "shown"), [
    ({"name": "small", "kind": "invariant", "expr": "now < 120 or counter.count < 3"},
     "counter"),
    ({"name": "e", "kind": "eventually", "expr": "nodes['other'].count > 99"}, "other"),
])
def test_a_violation_shows_the_states_its_property_reads_and_no_others(prop, shown):
    v = judged(prop)
    assert v.status is Status.VIOLATED, v
    states = [d.split(":")[0] for d in v.details if d.endswith(")") and ": " in d]
    assert states == [shown], v.details
