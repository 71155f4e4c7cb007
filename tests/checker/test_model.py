"""The model API every search uses: actions, the one step function, outcomes, and what a
transition says it did (the facts a partial-order reduction reads)."""

from __future__ import annotations

import pytest

from tests.checker.helpers import node, scenario
from twinfleet.checker import Crash, PropertySet, RunEvent, System
from twinfleet.checker.choices import PrefixChooser
from twinfleet.checker.driver import load
from twinfleet.checker.faults import CheckSettings
from twinfleet.checker.options import Semantics
from twinfleet.checker.semantics import Rules
from twinfleet.checker.world import Event
from twinfleet.runtime.contract.kinds import EventKind, FailureKind

pytestmark = pytest.mark.timeout(30)

PING_PONG = [node("ping", "Ping", rounds=3), node("pong", "Pong")]


def _system(tmp_path, nodes, **check):
    return System(load(scenario(tmp_path, nodes, **check)))


def test_step_with_each_outcomes_choices_gives_the_same_world(tmp_path):
    system = _system(tmp_path, [node("p", "Picker", options=[10, 20, 30])])
    (init,) = system.initial()
    (action,) = system.actions(init.world)
    assert action == RunEvent(0)
    outcomes = system.outcomes(init.world, action)
    assert [t.step.choices for t in outcomes] == [(0,), (1,), (2,)]
    for t in outcomes:
        again = system.step(init.world, action, PrefixChooser(t.step.choices))
        assert again.step == t.step and again.world.digest == t.world.digest
    assert [t.world.digest for t in system.successors(init.world)] == [
        t.world.digest for t in outcomes]


def test_a_transition_says_which_node_ran_what_it_sent_and_what_changed(tmp_path):
    system = _system(tmp_path, PING_PONG)
    (init,) = system.initial()
    (t,) = system.successors(init.world)  # pong handles the first ping
    pong = system.index["pong"]
    assert (t.event.target, t.event.method, t.event.kind) == (pong, "on_ping", EventKind.DELIVERY)
    assert t.changed == (pong,)
    assert [(e.target, e.method, e.priority, e.due) for e in t.sent] == [
        (system.index["ping"], "on_pong", 0, 0)]


def test_crash_actions_come_after_the_event_actions(tmp_path):
    system = _system(tmp_path, PING_PONG, faults={"crash": {"nodes": ["pong"]}})
    (init,) = system.initial()
    assert system.actions(init.world) == [RunEvent(0), Crash(system.index["pong"])]
    t = system.step(init.world, Crash(system.index["pong"]), PrefixChooser())
    assert t.event.kind is EventKind.CRASH and t.world.crashes == 1
    assert system.actions(t.world) == []  # the ping to pong was lost: nothing pending


def test_a_call_without_server_times_out_as_a_timeout_event(tmp_path):
    system = _system(tmp_path, [node("client", "Client", service="/nobody")])
    reasons = []
    for init in system.initial():  # one initial world per reason, as live gives either
        (ev,) = init.world.events
        assert (ev.kind, ev.method, ev.due) == (EventKind.TIMEOUT, "on_reply", 50)
        assert not ev.kind.is_message
        reasons.append(ev.args[0].reason)
    assert reasons == ["no server", "timeout"]


def test_a_forced_choice_that_does_not_exist_is_a_typed_failure(tmp_path):
    system = _system(tmp_path, [node("p", "Picker", options=[10, 20, 30])])
    (init,) = system.initial()
    t = system.step(init.world, RunEvent(0), PrefixChooser((5,)))
    assert t.failure is not None and t.failure.kind is FailureKind.CHOICE_MISMATCH
    props = PropertySet.from_scenario(system.scenario)
    assert props.check_failure(t.failure).property == "no_failure"


def test_relaxed_timing_keeps_stream_order_only():
    rules = Rules(Semantics.ROS, settings=CheckSettings(latency=(0, 5)))
    pending: list[Event] = []
    rules.add(pending, Event(0, EventKind.TIMER, 1, "t", 1, (), 0))
    rules.add(pending, Event(3, EventKind.DELIVERY, 1, "m", 0, (1,), 0))
    rules.add(pending, Event(1, EventKind.DELIVERY, 1, "m", 0, (2,), 0))  # clamped to 3
    # same channel (sender 0 to node 1), another stream (handler): clamped to 3 as well
    rules.add(pending, Event(2, EventKind.DELIVERY, 1, "n", 0, (), 0))
    events = sorted(pending, key=Event.sort_key)
    assert [(e.kind, e.method, e.due, e.rank) for e in events] == [
        (EventKind.TIMER, "t", 0, 0), (EventKind.DELIVERY, "m", 3, 0),
        (EventKind.DELIVERY, "m", 3, 1), (EventKind.DELIVERY, "n", 3, 2)]
    assert rules.enabled(events) == [0]
    assert rules.enabled_within(events, 2) == {0}
    # the second "m" waits for the first; "n" is the head of its own stream
    assert rules.enabled_within(events, 3) == {0, 1, 3}
    assert rules.enabled_within(events, None) == {0, 1, 3}
    assert rules.stream_head(events, events[2]) is events[1]
    assert Rules(Semantics.REBECA).enabled_within(events, None) == {0, 1, 2, 3}


def test_properties_say_what_they_read(tmp_path):
    path = scenario(tmp_path, PING_PONG, properties=[
        {"name": "b", "kind": "invariant", "expr": "pong.received <= 3"},
        {"name": "w", "kind": "within", "expr": "ping.sent == 3", "within_ms": 10}])
    props = PropertySet.from_scenario(load(path))
    assert props.reads() == (frozenset({0, 1}), False)
