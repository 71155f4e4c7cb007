"""The search's rules rewritten for speed give every value the reviewed code gave.

`Rules.enabled` and `System._apply` (pinned in test_reduction_rules.py) were rewritten:
Rules 2 and 4 from one pass (each node's lowest handler priority, then the nodes Rule 4
keeps; with no two nodes of one instance priority, the lowest pair of (instance priority,
handler priority)), and a step's pending events under semantics without send order taken
as slices (`Rules.remove` and `Rules.add` change no event there). The code they replaced
is kept below (the enabling rules as they were, and the world a step built from `remove`
and `add`); old and new run on the worlds of c1a_rebeca, c1a and generated systems, and
on random event lists under every kind of priority setting.
"""

from __future__ import annotations

import dataclasses
import random
from collections import deque
from collections.abc import Iterator, Sequence
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings

from tests.checker.program_systems import systems, write_scenario
from twinfleet.checker import System
from twinfleet.checker.driver import load
from twinfleet.checker.semantics import Rules, Semantics, _earliest_sent
from twinfleet.checker.transition import RunEvent, Step, Variant
from twinfleet.checker.world import Event, World
from twinfleet.runtime.contract.kinds import EventKind

pytestmark = pytest.mark.timeout(300)

LAUNCH = Path(__file__).resolve().parents[2] / "twinfleet" / "launch"


def enabled_before(rules: Rules, events: Sequence[Event]) -> list[int]:
    """`Rules.enabled` and `Rules._across_nodes` as they were reviewed."""
    if not events:
        return []
    now = events[0].due
    if len(events) == 1 or events[1].due != now:
        return [0]
    group = []
    best: dict[int, int] = {}
    for i, ev in enumerate(events):
        if ev.due != now:
            break
        group.append(i)
        if ev.priority < best.get(ev.target, ev.priority + 1):
            best[ev.target] = ev.priority
    picked = [i for i in group if events[i].priority == best[events[i].target]]
    if rules.fifo:
        return _earliest_sent(events, picked)
    if len(best) <= 1:
        return picked
    if rules.global_priority:
        top = min(events[i].priority for i in picked)
        return [i for i in picked if events[i].priority == top]
    if not rules.node_priorities:
        return picked
    prios = rules.node_priorities
    top = min(prios[events[i].target] for i in picked)
    return [i for i in picked if prios[events[i].target] == top]


def world_before(system: System, world: World, index: int, v: Variant) -> World:
    """The world `System._apply` built for a run event as it was reviewed."""
    ev = world.events[index]
    pending = system.rules.remove(world.events, index)
    for e in v.events:
        system.rules.add(pending, e)
    states = list(world.states)
    states[ev.target] = v.state
    return system._world(ev.due, tuple(states), pending, world, world.crashes)


def _value(ev: Event) -> tuple[object, ...]:
    """Every field of `ev` (under `ros` a step's ranked events are new objects each time)."""
    return (ev.due, ev.kind, ev.target, ev.method, ev.sender, ev.args, ev.priority,
            ev.reply_to, ev.rank, ev.key, ev.deadline, ev.sk)


def priority_variants(rules: Rules) -> list[Rules]:
    """`rules`, and under `rebeca` the same with tied, distinct, no instance priorities and
    with global priority: every path of `enabled` on the same worlds."""
    if rules.fifo:
        return [rules]
    n = len(rules.node_priorities)
    return [rules, *(dataclasses.replace(rules, node_priorities=p, global_priority=g)
                     for p in ((), tuple(range(n, 0, -1)), tuple(i % 2 for i in range(n)))
                     for g in (False, True))]


def worlds(system: System, limit: int) -> Iterator[World]:
    """Up to `limit` distinct worlds of `system`, breadth first (failures not followed)."""
    todo = deque(t.world for t in system.initial())
    seen: set[int | bytes] = set()
    while todo and len(seen) < limit:
        world = todo.popleft()
        if world.key in seen:
            continue
        seen.add(world.key)
        yield world
        todo.extend(t.world for t in system.successors(world) if t.failure is None)


def assert_as_before(system: System, limit: int) -> int:
    """Compare the rewritten rules with the reviewed ones on `system`'s worlds; return how
    many worlds had more than one event enabled (the comparison must see some)."""
    variants = priority_variants(system.rules)
    several = 0
    for world in worlds(system, limit):
        events = world.events
        for rules in variants:
            assert rules.enabled(events) == enabled_before(rules, events), (rules, events)
        enabled = system.rules.enabled(events)
        several += len(enabled) > 1
        for index in enabled:
            action = RunEvent(index)
            for v in system.variants(world, action):
                new, old = system._apply(world, action, v), world_before(system, world,
                                                                          index, v)
                assert [_value(e) for e in new.world.events] == [
                    _value(e) for e in old.events]
                assert (new.world.key, new.world.states) == (old.key, old.states)
                ev = events[index]
                changed = (ev.target,) if v.state is not world.states[ev.target] else ()
                assert (new.step, new.event, new.changed, new.sent, new.failure) == (
                    Step(action, v.choices, v.options), ev, changed, v.events, v.failure)
    return several


@pytest.mark.parametrize(("name", "limit"), [("c1a_rebeca", 6000), ("c1a", 3000)])
def test_the_paper_cases(name: str, limit: int) -> None:
    system = System(load(LAUNCH / f"{name}.yaml"))
    assert assert_as_before(system, limit) > 100


@settings(max_examples=25, deadline=None, suppress_health_check=list(HealthCheck))
@given(doc=systems())
def test_generated_systems(tmp_path_factory: pytest.TempPathFactory, doc: dict) -> None:
    path = write_scenario(doc, tmp_path_factory.mktemp("gen") / "system.yaml")
    assert_as_before(System(load(path)), 300)


def _event(rng: random.Random) -> Event:
    return Event(rng.randrange(3), rng.choice([EventKind.DELIVERY, EventKind.TIMER]),
                 rng.randrange(5), rng.choice(["a", "b"]), rng.randrange(-1, 5),
                 (rng.randrange(2),), rng.randrange(3), rank=rng.randrange(2))


def test_random_events_under_every_priority_setting() -> None:
    rng = random.Random(11)
    settings_ = [Rules(Semantics.ROS), *(Rules(Semantics.REBECA, p, g) for p in (
        (), (1, 2, 3, 4, 5), (5, 1, 4, 2, 3), (1, 1, 2, 2, 3), (0, 0, 0, 0, 0))
        for g in (False, True))]
    for _ in range(3000):
        events = tuple(sorted((_event(rng) for _ in range(rng.randrange(10))),
                              key=Event.sort_key))
        for rules in settings_:
            assert rules.enabled(events) == enabled_before(rules, events)
