"""Rule 7: a late `@every` tick makes the checker branch over the ticks a late node skips to.

TickCounter ticks every 20 ms from t=20 and at t=90 looks how many ticks it had: four
on time. With `check.timer_lateness: [0, 45]` a tick due at t may leave its queue up to
45 ms late; from a lateness of 40 ms (two periods) the next tick, due t + 20, is a period
or more past, so the runtime skips to the first tick after t + 40, which is t + 60
(`runtime.contract.rules.next_tick`); the checker's next tick is a branch: t + 20 or
t + 60, and the node may have seen 2, 3 or 4 ticks at t=90.
"""

from __future__ import annotations

import pytest

from tests.checker.helpers import node, replay_confirms, run, scenario
from twinfleet.checker.choices import PrefixChooser
from twinfleet.checker.driver import load
from twinfleet.checker.system import System
from twinfleet.checker.transition import RunEvent
from twinfleet.runtime.contract.kinds import EventKind

pytestmark = pytest.mark.timeout(60)

NODES = [node("counter", "TickCounter")]


def on_time(seen: tuple[int, ...]) -> list[dict[str, str]]:
    return [{"name": "on_time", "kind": "invariant", "expr": f"counter.seen in {seen}"}]


def test_without_timer_lateness_every_tick_is_on_time(tmp_path):
    assert run(scenario(tmp_path, NODES, properties=on_time((-1, 4)))).status == "holds"


def test_a_lateness_of_two_periods_skips_the_missed_ticks(tmp_path):
    path = scenario(tmp_path, NODES, properties=on_time((-1, 4)), name="late",
                    timer_lateness=[0, 45])
    result = run(path)
    assert result.status == "violated", result.summary()
    assert result.violation.property == "on_time"
    assert "timers 0-45 ms late" in result.summary()
    assert replay_confirms(result)
    path = scenario(tmp_path, NODES, properties=on_time((-1, 2, 3, 4)), name="skips",
                    timer_lateness=[0, 45])
    assert run(path).status == "holds"
    # Late, but never two periods late: nothing is skipped.
    path = scenario(tmp_path, NODES, properties=on_time((-1, 4)), name="late39",
                    timer_lateness=[0, 39])
    assert run(path).status == "holds"


def test_the_next_tick_is_a_branch_only_where_the_lateness_reaches_a_period_behind(tmp_path):
    for late, expected in (([0, 39], [40]), ([0, 45], [40, 80]), ([40, 45], [80]),
                           ([0, 60], [40, 80, 100])):
        system = System(load(scenario(tmp_path, NODES, name=f"l{late[0]}-{late[1]}",
                                      timer_lateness=late)))
        (first,) = [t.world for t in system.initial()]
        assert first.events[0].kind is EventKind.PERIODIC and first.events[0].due == 20
        ticks, chooser = [], PrefixChooser()
        while True:  # every branch of the first tick's run, in the odometer's order
            t = system.step(first, RunEvent(0), chooser)
            ticks += [ev.due for ev in t.world.events if ev.kind is EventKind.PERIODIC]
            prefix = chooser.next_prefix()
            if prefix is None:
                break
            chooser = PrefixChooser(prefix)
        assert ticks == expected, late


def test_a_bad_timer_lateness_is_one_line_naming_the_key(tmp_path):
    from twinfleet.runtime.scenario.spec import ScenarioError
    with pytest.raises(ScenarioError, match=r"check\.timer_lateness"):
        load(scenario(tmp_path, NODES, name="bad", timer_lateness=[5, 1]))


def test_a_simulation_draws_the_next_tick_by_the_models_timer_lateness(tmp_path):
    import random

    from twinfleet.checker.choices import LatenessSite
    from twinfleet.checker.sampling import SamplingChooser
    from twinfleet.checker.statistical import timed_system
    from twinfleet.checker.timing import Histogram, TimingModel

    model = TimingModel(timer_lateness=Histogram((0, 10, 50), (0.5, 0.25, 0.25)))
    system, _ = timed_system(load(scenario(tmp_path, NODES, name="sim")), model)
    assert system.settings.timer_lateness == (0, 50)
    rng = random.Random(7)
    draws = [SamplingChooser(rng, model).branch(2, LatenessSite((0, 40))) for _ in range(4000)]
    assert 0.72 < draws.count(0) / len(draws) < 0.78  # lateness 0 or 10: 0.75; 50: 0.25
    never = TimingModel(timer_lateness=Histogram((0,), (1.0,)))
    assert {SamplingChooser(rng, never).branch(2, LatenessSite((0, 40)))
            for _ in range(200)} == {0}
