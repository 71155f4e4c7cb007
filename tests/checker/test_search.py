"""Search orders agree, limits and Ctrl-C stop cleanly, and the semantics' FIFO bookkeeping."""

from __future__ import annotations

import pytest

from tests.checker.helpers import node, scenario
from twinfleet.checker import Limits, PropertySet, Search, System, bfs, dfs
from twinfleet.checker.driver import load
from twinfleet.checker.faults import CheckSettings
from twinfleet.checker.options import Semantics
from twinfleet.checker.semantics import Rules
from twinfleet.checker.world import Event
from twinfleet.runtime.contract.kinds import EventKind
from twinfleet.runtime.scenario.spec import ScenarioError

pytestmark = pytest.mark.timeout(30)

MODELS = {
    "sums": [node("two", "TwoSender"), node("four", "FourSender"), node("sum", "Summer")],
    "ticks": [node("a", "TickA"), node("b", "TickB")],
    "waiters": [node("a", "WaiterA", inbox="/go_a", outbox="/go_b", first=True),
                node("b", "WaiterB", inbox="/go_b", outbox="/go_a")],
    "picker": [node("p", "Picker", second=[0, 100])],
}


def _system(path):
    scen = load(path)
    props = PropertySet.from_scenario(scen)
    return System(scen, properties=props), props


@pytest.mark.parametrize("model", sorted(MODELS))
@pytest.mark.parametrize("semantics", ["ros", "rebeca"])
def test_bfs_and_dfs_agree(tmp_path, model, semantics):
    system, props = _system(scenario(tmp_path, MODELS[model], semantics=semantics))
    a = bfs(system, props).statistics
    b = dfs(system, props).statistics
    assert (a.states, a.transitions) == (b.states, b.transitions)


def test_ctrl_c_stops_cleanly(tmp_path):
    system, props = _system(scenario(tmp_path, [node("c", "Counter", modulo=0)]))
    seen = []

    def interrupt(stats):
        seen.append(stats)
        if stats.states > 30:
            raise KeyboardInterrupt

    outcome = Search(system, props, progress=interrupt, progress_interval=0).run("bfs")
    assert outcome.status == "unknown"
    assert outcome.reason == "interrupted (Ctrl-C)"
    assert outcome.statistics.states > 30
    assert seen


def test_max_time_limit(tmp_path):
    system, props = _system(scenario(tmp_path, [node("c", "Counter", modulo=0)]))
    outcome = Search(system, props, Limits(max_time_s=0.05)).run("dfs")
    assert outcome.status == "unknown"
    assert "max-time" in outcome.reason


def test_random_walks_are_reproducible(tmp_path):
    path = scenario(tmp_path, MODELS["sums"])
    system, props = _system(path)
    runs = [Search(system, props).run("random", walks=20, seed=7).statistics for _ in range(2)]
    assert (runs[0].states, runs[0].transitions) == (runs[1].states, runs[1].transitions)
    assert runs[0].transitions == 20 * 3  # every walk: 3 deliveries, then nothing pending


def test_fifo_ranks_and_latency_clamp():
    DELIVERY, TIMER = EventKind.DELIVERY, EventKind.TIMER
    ros = Rules(Semantics.ROS, settings=CheckSettings(latency=(0, 5)))
    pending: list[Event] = []
    ros.add(pending, Event(3, DELIVERY, 1, "m", 0, (), 0))
    ros.add(pending, Event(1, DELIVERY, 1, "m", 0, (), 0))  # clamped behind the first
    ros.add(pending, Event(3, TIMER, 1, "t", 1, (), 0))  # another channel
    assert [(e.due, e.rank) for e in pending] == [(3, 0), (3, 1), (3, 0)]
    events = sorted(pending, key=Event.sort_key)
    enabled = ros.enabled(events)
    assert sorted((events[i].kind, events[i].rank) for i in enabled) == [
        (DELIVERY, 0), (TIMER, 0)]
    first = next(i for i in enabled if events[i].kind == DELIVERY)
    assert [e.rank for e in ros.remove(events, first)] == [0, 0]
    rebeca = Rules(Semantics.REBECA)
    assert len(rebeca.enabled(events)) == 3


def test_bad_latency_is_a_scenario_error(tmp_path):
    with pytest.raises(ScenarioError, match=r"check.latency"):
        System(load(scenario(tmp_path, MODELS["sums"], latency=[5])))
    with pytest.raises(ScenarioError, match=r"latency must be"):
        System(load(scenario(tmp_path, MODELS["sums"], name="neg", latency=[5, 1])))


def test_two_servers_of_one_service_is_a_scenario_error(tmp_path):
    path = scenario(tmp_path, [node("a1", "Adder"), node("a2", "Adder")])
    with pytest.raises(ScenarioError, match=r"served by both a1 and a2"):
        System(load(path))
