"""What the one-process search pays per transition: a revisit within a BFS level costs no
store probe, growth sampling splits each node state into fields once, and a handler run
of the same node state and event at another time is not repeated."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from types import SimpleNamespace

import pytest

from tests.checker.helpers import node, scenario
from twinfleet import Context, Empty, Node, every, subscribe
from twinfleet.checker import CheckOptions, PropertySet, Search, System, check
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


# ------------------------------------------------ handler runs kept across times


@dataclass
class _Count:
    """How many ticks were sent (up to three)."""

    sent: int = 0


class Ticker(Node):
    """Publishes the same message every 10 ms, three times: its listeners see it at
    10, 20 and 30 ms in the same state."""

    def initial_state(self) -> _Count:
        return _Count()

    @every(10)
    def tick(self, ctx: Context) -> None:
        if self.state.sent < 3:
            self.state.sent += 1
            ctx.publish("/tick", Empty())


@dataclass
class _Nothing:
    """A listener that keeps nothing."""

    flag: bool = False


class Listener(Node):
    """Answers every tick the same way, whatever the time."""

    def initial_state(self) -> _Nothing:
        return _Nothing()

    @subscribe("/tick")
    def on_tick(self, ctx: Context, msg: Empty) -> None:
        ctx.publish("/heard", Empty())


class ClockListener(Listener):
    """Answers every tick the same way, but reads the clock first."""

    @subscribe("/tick")
    def on_tick(self, ctx: Context, msg: Empty) -> None:
        if ctx.now() >= 0:
            ctx.publish("/heard", Empty())


def _listeners(tmp_path, cls: str):
    here = "tests.checker.test_search_costs:"
    return scenario(tmp_path, [{"name": "ticker", "class": here + "Ticker"},
                               {"name": "listener", "class": here + cls}],
                    name=cls, latency=[0, 1])


@pytest.mark.parametrize(("cls", "runs"), [("Listener", 1), ("ClockListener", 6)])
def test_a_handler_that_does_not_read_the_clock_runs_once_per_state_and_event(
        tmp_path, monkeypatch, cls, runs):
    # The same (node state, event) at 10, 20 and 30 ms, each 0 or 1 ms late: a kept run gives
    # its effects again (each latency branch of its reply too) unless the handler read the
    # clock (then once per time: 6); the graph is the one that running every handler gives.
    from twinfleet.checker.runner import Runner

    ran: Counter[str] = Counter()
    exec_ = Runner._exec

    def counting(self, ev, *args):
        ran[ev.method] += 1
        return exec_(self, ev, *args)

    monkeypatch.setattr(Runner, "_exec", counting)
    path = _listeners(tmp_path, cls)
    kept = check(path, CheckOptions(reduction="none"))
    assert ran["on_tick"] == runs  # verified by `_same_again`, not a second `_exec`
    every_run = check(path, CheckOptions(reduction="none", transition_cache=False))
    assert ran["on_tick"] > runs + 3
    assert (kept.statistics.states, kept.statistics.transitions) == \
        (every_run.statistics.states, every_run.statistics.transitions)
    assert kept.status == every_run.status == "holds"
