"""The partial-order reduction starts late: a search's first worlds are searched unreduced.

A small search cannot repay what the reduction costs before it saves anything: a
persistent set computed per world, the send relation learned level by level, and a
restart whenever a level that reduced some world learned a new send (`checker.reduction`).
So a `por` search begins unreduced, only learning the send relation (every world is
expanded fully, so nothing relies on the relation yet and it grows in place), until it
has stored `reduce_from` worlds (`checker.options.REDUCE_FROM`). A search that ends before
then was an unreduced search, and says so. One that gets there decides by a sample of the
worlds it is about to expand: if at least `ASIDE_SHARE` of them have a persistent set
smaller than everything, the search starts again from scratch, reduced from its first
world with everything learned so far, exactly as after a restart (its graph, counts and
traces are those of a search reduced from the start); if fewer, the reduction steps aside
and the search goes on unreduced where it is, having lost nothing.

Sound either way: the unreduced part is the unreduced search, and the restart is the
reduced search's own restart (what a reduced search finds does not depend on when the
relation it starts with was learned, only on the relation being checked as it goes).
"""

from __future__ import annotations

from collections.abc import Iterable
from enum import Enum, unique
from itertools import islice
from typing import TYPE_CHECKING, Final

if TYPE_CHECKING:
    from twinfleet.checker.reduction import Reduction
    from twinfleet.checker.world import World

# Worlds of the next level whose persistent sets decide whether the reduction starts: a
# closure costs 25-45 us, so the sample costs a few ms; every shipped case that reduces
# does so in more than a third of its worlds, the two-phase commits in none.
SAMPLE: Final = 200


@unique
class Start(Enum):
    """What a search waiting for its reduction does at the start of a level."""

    WAIT = "wait"  # fewer than `reduce_from` worlds stored: on, unreduced
    REDUCE = "reduce"  # start again from scratch, reduced
    ASIDE = "aside"  # the reduction would not pay: on, unreduced, for good


def start(reduction: Reduction, stored: int, frontier: Iterable[World]) -> Start:
    """At the start of a level of a search waiting for `reduction` (`Reduction.waiting`),
    `stored` worlds stored, `frontier` the worlds left to expand: what the search does. The
    relation learned so far enters the reduction's relation in any case. A reduction that
    stepped aside stays waiting, so that a search sharing it (`checker.cluster`, whose
    workers take it over only then) expands every world fully.)"""
    if reduction.stale:
        reduction.learned()
    if reduction.aside is not None or reduction.disabled or stored < reduction.reduce_from:
        return Start.WAIT
    # here: the reduction's modules are loaded only where a search may reduce
    from twinfleet.checker.reduction import ASIDE_SHARE, uncounted

    with uncounted(reduction):  # no world of the sample is expanded
        reduced, sampled = _sample(reduction, frontier)
    if sampled and reduced >= ASIDE_SHARE * sampled:
        reduction.waiting = False
        reduction.stats.prefix = stored
        return Start.REDUCE
    reduction.aside = (f"por stepped aside: {reduced:,} of {sampled:,} worlds sampled after the "
                       f"first {stored:,} would be reduced, under {ASIDE_SHARE:.0%}; the search "
                       "ran unreduced")
    return Start.ASIDE


def _sample(reduction: Reduction, frontier: Iterable[World]) -> tuple[int, int]:
    """(worlds with a persistent set smaller than everything, worlds sampled) among the
    first `SAMPLE` of `frontier` with an event pending."""
    worlds = list(islice((w for w in frontier if w.events), SAMPLE))
    return sum(reduction.persistent(w) is not None for w in worlds), len(worlds)
