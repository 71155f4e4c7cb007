"""What makes a simulation cheap changes none of its results: worlds keyed only when read,
event keys kept by message identity, invariants checked after steps that change a state,
and a run that ends once no node state can change any more ("settled")."""

from __future__ import annotations

from dataclasses import dataclass

from tests.checker.models import Num
from twinfleet import Context, Node, every, subscribe, testing
from twinfleet.checker.properties import PropertySet
from twinfleet.checker.simulate import Simulator
from twinfleet.checker.statistical import timed_system
from twinfleet.checker.system import System
from twinfleet.checker.timing import Histogram, TimingModel

MODEL = TimingModel(Histogram((1, 2, 3), (0.5, 0.25, 0.25), 100))


@dataclass
class CountState:
    """State of Counter."""

    count: int = 0


class Counter(Node):
    """Counts to 5 on a 10-ms tick, then keeps telling the last count for ever."""

    def initial_state(self) -> CountState:
        return CountState()

    @every(10)
    def tick(self, ctx: Context) -> None:
        if self.state.count < 5:
            self.state.count += 1
        ctx.publish("/count", Num(self.state.count))


@dataclass
class HeardState:
    """State of Hearer."""

    last: int = 0


class Hearer(Node):
    """Keeps the last count heard."""

    def initial_state(self) -> HeardState:
        return HeardState()

    @subscribe("/count")
    def on_count(self, ctx: Context, msg: Num) -> None:
        self.state.last = msg.value


def _simulator(extra: list[object] | None = None, *, reuse: bool = True) -> Simulator:
    props = [testing.invariant("small", "h.last <= 5"), testing.eventually("five", "h.last == 5"),
             testing.eventually("six", "h.last == 6"), *(extra or [])]
    scenario = testing.system({"c": Counter, "h": Hearer}, props, name="counting")
    system, properties = timed_system(scenario, MODEL)
    return Simulator(system, properties, MODEL, seed=3, horizon_ms=5_000, max_steps=100_000,
                     reuse=reuse)


def test_a_run_ends_once_no_state_can_change_with_the_results_of_the_whole_run() -> None:
    short, whole = _simulator(), _simulator(reuse=False)
    for i in range(2):
        a, b = short.run(i), whole.run(i)
        assert a.index == b.index == i
        assert a.ended == "settled" and b.ended == "horizon"
        assert a.steps < 200 < 800 < b.steps
        assert a.violated == b.violated == ("six",)
        assert a.first is not None and b.first is not None
        assert a.first[0].shape == b.first[0].shape == "horizon"


def test_a_property_that_reads_the_time_keeps_the_run_to_its_horizon() -> None:
    sim = _simulator([testing.invariant("early", "now < 30_000")])
    assert sim.run(0).ended == "horizon"


def test_a_simulation_keys_its_worlds_only_when_asked_with_the_same_key() -> None:
    scenario = testing.system({"c": Counter, "h": Hearer}, name="counting")
    props = PropertySet.from_scenario(scenario)
    keyed = System(scenario, properties=props, latency=(1, 3))
    lazy = System(scenario, properties=props, latency=(1, 3), keyed=False)
    a, b = keyed.initial()[0].world, lazy.initial()[0].world
    assert b._key is None and a.key == b.key and b._key == a.key
    ta, tb = next(keyed.successors(a)), next(lazy.successors(b))
    assert tb.world._key is None and ta.world.key == tb.world.key
