"""Building a step's world the short way gives the world the long way gives.

A step's new events are inserted into its world's sorted others (`sort_events` with
`appended`), and a builder keys a world from its node states' joined hashes, kept by
the tuple of states (`joined_key`, without reading ranks where every rank is 0): the
same order and the same keys as sorting everything and `fast_key` over each part. A
search asks `Rules.may_drop` before `Rules.droppable`: False only where that is empty.
"""

from __future__ import annotations

import random
from collections import deque

import pytest

from tests.checker.helpers import node, scenario
from twinfleet.checker import System
from twinfleet.checker.driver import load
from twinfleet.checker.semantics import Rules, Semantics
from twinfleet.checker.world import Event, World, fast_key, joined_key, sort_events
from twinfleet.runtime.contract.kinds import EventKind

pytestmark = pytest.mark.timeout(120)


def _event(rng: random.Random) -> Event:
    return Event(rng.randrange(3), rng.choice([EventKind.DELIVERY, EventKind.TIMER]),
                 rng.randrange(3), rng.choice(["a", "b"]), rng.randrange(-1, 2),
                 (rng.randrange(2),), 0, rank=rng.randrange(2),
                 deadline=rng.choice([None, 0, 5]))


def test_appended_events_go_where_a_stable_sort_puts_them():
    rng = random.Random(7)
    for _ in range(3000):
        # few distinct events: equal sort keys (the stable order decides) are common
        rest = sorted((_event(rng) for _ in range(rng.randrange(9))), key=Event.sort_key)
        new = [_event(rng) for _ in range(rng.randrange(7))]
        expected = sorted(rest + new, key=Event.sort_key)
        got = sort_events(rest + new, len(new))
        assert [id(e) for e in got] == [id(e) for e in expected]
        assert [id(e) for e in sort_events(new + rest)] == [
            id(e) for e in sorted(new + rest, key=Event.sort_key)]


def test_joined_key_is_fast_key():
    rng = random.Random(3)
    for _ in range(500):
        events = tuple(sort_events([_event(rng) for _ in range(rng.randrange(6))]))
        hashes = [rng.randbytes(8) for _ in range(rng.randrange(1, 4))]
        obligations = rng.choice([(), ("w",), ("v", "w")])
        crashes = rng.randrange(2)
        assert joined_key(b"".join(hashes), events, obligations, crashes) == fast_key(
            hashes, events, obligations, crashes)
        unranked = tuple(e.with_rank(0) for e in events)
        assert joined_key(b"".join(hashes), unranked, obligations, crashes,
                          ranked=False) == fast_key(hashes, unranked, obligations, crashes)


PP = [node("ping", "Ping", rounds=3), node("pong", "Pong")]
MODELS = {
    "service": ([node("client", "Client"), node("adder", "Adder")], {"latency": [0, 2]}),
    "within": ([node("c", "Counter", modulo=0, cap=5)],
               {"properties": [{"name": "w", "kind": "within", "expr": "c.count >= 3",
                                "within_ms": 300}]}),
    "crash": (PP, {"faults": {"crash": {"nodes": ["ping", "pong"], "max": 2}}}),
    "sums": ([node("two", "TwoSender"), node("four", "FourSender"), node("sum", "Summer")],
             {"latency": [0, 1]}),
}


@pytest.mark.parametrize("model", sorted(MODELS))
@pytest.mark.parametrize("semantics", ["ros", "rebeca"])
def test_every_built_world_has_the_key_of_its_parts(tmp_path, model, semantics):
    nodes, extra = MODELS[model]
    system = System(load(scenario(tmp_path, nodes, semantics=semantics, name=model, **extra)))
    todo = deque(t.world for t in system.initial())
    seen: set[int | bytes] = set()
    ranked = 0
    while todo and len(seen) < 3000:
        world = todo.popleft()
        # the key a world computes itself from its parts when it was built without one
        assert world.key == World(world.now, world.states, world.events, world.obligations,
                                  crashes=world.crashes).key
        assert list(world.events) == sorted(world.events, key=Event.sort_key)
        ranked += any(e.rank for e in world.events)
        if world.key in seen:
            continue
        seen.add(world.key)
        todo.extend(t.world for t in system.successors(world) if t.failure is None)
    assert len(seen) > 2
    if semantics == "rebeca":
        assert ranked == 0  # send order ignored: the builder reads no ranks
    elif model in ("crash", "sums"):
        assert ranked > 0  # FIFO ranks: read into the key


@pytest.mark.parametrize("semantics", [Semantics.ROS, Semantics.REBECA])
def test_may_drop_is_false_only_where_nothing_is_droppable(semantics):
    rng = random.Random(11)
    for _ in range(3000):
        depths = {(t, m): rng.randrange(1, 4) for t in range(3) for m in ("a", "b")
                  if rng.random() < 0.7}
        rules = Rules(semantics, depths=depths)
        events = sort_events([_event(rng) for _ in range(rng.randrange(10))])
        if not rules.may_drop(events):
            assert rules.droppable(events) == []
