"""The rules both drivers apply (`runtime.contract.rules`): the live core follows them, and
the checker's branches are exactly the outcomes they allow."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from twinfleet import Context, Node, every
from twinfleet.runtime.contract.kinds import EventKind
from twinfleet.runtime.contract.rules import (
    first_tick,
    keep_last_depth,
    keep_last_excess,
    next_tick,
    next_ticks,
)
from twinfleet.runtime.core.due import DueEntries


class Ticker(Node):
    @every(20, phase_ms=5)
    def tick(self, ctx: Context) -> None:
        pass


def test_first_tick_is_the_first_grid_point_strictly_after_now():
    assert [first_tick(20, 5, now) for now in (0, 4, 5, 24, 25, 26)] == [25, 25, 25, 25, 45, 45]
    assert first_tick(100, 0, 0) == 100


def test_a_tick_a_period_or_more_behind_skips_the_missed_periods():
    assert next_tick(25, 20, 5, 25) == 45  # on time
    assert next_tick(25, 20, 5, 64) == 45  # late, but the next one is not a period past
    assert next_tick(25, 20, 5, 65) == 85  # the next one (45) is a full period past
    assert next_tick(25, 20, 5, 1000) == 1005


@given(st.integers(1, 50), st.integers(0, 49), st.integers(0, 20), st.integers(0, 300),
       st.integers(0, 300))
def test_next_ticks_are_the_distinct_next_ticks_of_every_lateness(period, phase, k, a, b):
    phase %= period
    due = phase + (k + 1) * period
    low, high = min(a, b), max(a, b)
    every_late = {}
    for late in range(low, high + 1):
        every_late.setdefault(next_tick(due, period, phase, due + late), late)
    assert next_ticks(due, period, phase, (low, high)) == tuple(sorted(every_late.items()))


@given(st.integers(0, 200))
def test_the_live_core_arms_the_next_tick_by_the_rule(late):
    due = DueEntries(Ticker("t"))
    due.start(Ticker("t").spec().of_kind("every"), 0)
    released = due.pop_due(25 + late)
    assert (released[0][0], released[0][2].kind) == (25, EventKind.PERIODIC)
    # The tick after it, released at once when it is due by then too.
    after = released[1][0] if len(released) > 1 else due.next_due()
    assert after == next_tick(25, 20, 5, 25 + late)


def test_keep_last_drops_the_excess_over_its_depth():
    assert [keep_last_depth(d) for d in (0, 1, 10)] == [1, 1, 10]
    assert [keep_last_excess(w, 2) for w in (0, 1, 2, 3, 5)] == [0, 0, 0, 1, 3]
