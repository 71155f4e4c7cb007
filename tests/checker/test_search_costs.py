"""What the one-process search pays per transition: a revisit within a BFS level costs no
store probe, and growth sampling splits each node state into fields once."""

from __future__ import annotations

from collections import Counter
from types import SimpleNamespace

import pytest

from tests.checker.helpers import node, scenario
from twinfleet.checker import PropertySet, Search, System
from twinfleet.checker.driver import load
from twinfleet.checker.growth import GrowthWatch

pytestmark = pytest.mark.timeout(30)

SUMS = [node("two", "TwoSender"), node("four", "FourSender"), node("sum", "Summer")]


def _search(path):
    scen = load(path)
    props = PropertySet.from_scenario(scen)
    return Search(System(scen, properties=props), props)


@pytest.mark.parametrize("semantics", ["ros", "rebeca"])
def test_a_bfs_safety_search_asks_the_store_once_per_new_world(tmp_path, semantics):
    search = _search(scenario(tmp_path, SUMS, semantics=semantics))
    store, calls = search.store, []
    add = store.add

    def counted(key, parent, *, terminal=False):
        calls.append(key)
        return add(key, parent, terminal=terminal)

    store.add = counted  # type: ignore[method-assign]
    stats = search.run("bfs").statistics
    assert stats.transitions > stats.states  # revisits happen
    assert len(calls) == stats.states  # the old loop asked once per transition


def test_growth_sampling_splits_each_node_state_once():
    decoded: Counter[bytes] = Counter()

    def decode(i, data):
        decoded[data] += 1
        return {"count": int(data)}

    watch = GrowthWatch(("c",), decode)
    parent = SimpleNamespace(states=(b"0",))
    for child in (b"1", b"2", b"1"):  # one parent, siblings that change the same node
        watch.observe(parent, SimpleNamespace(changed=(0,), world=SimpleNamespace(states=(child,))))
    assert watch.sampled == 3
    assert decoded == {b"0": 1, b"1": 1, b"2": 1}  # the old sampling split b"0" three times
