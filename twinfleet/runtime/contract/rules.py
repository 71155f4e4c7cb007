"""Rules of the contract that both drivers apply: the live node core and the checker.

A node's timers and its KEEP_LAST queues behave by a few small rules. The live
core (`runtime.core.due`, `runtime.core.node_core`) and the checker
(`checker.topology`, `checker.runner`, `checker.semantics`) both call these
functions instead of each stating the rule again, so the model cannot drift
from what a node process does.

Timers. An `@every(period, phase_ms=phase)` timer ticks on the grid
``phase + k * period`` (k >= 1). Its first tick is the first grid point strictly
after the time it is armed (`first_tick`). After a tick due at ``due`` leaves
the timer queue at ``now`` (``now - due`` is its lateness), the next one is due
one period later, unless that is already a full period or more in the past: a
process that fell that far behind (a suspended or starved process) skips the
missed periods and ticks next at the first grid point after ``now``
(`next_tick`). The checker, which runs every event at its due time, branches
over the next ticks a lateness range allows (`next_ticks`).

KEEP_LAST. A subscription declared with depth d holds at most ``max(1, d)``
received but not yet handled messages (`keep_last_depth`); when a message
arrives with that many waiting, the oldest waiting one is dropped
(`keep_last_excess`).
"""

from __future__ import annotations


def first_tick(period: int, phase: int, now_ms: int) -> int:
    """The first tick of an `@every(period, phase_ms=phase)` timer strictly after `now_ms`."""
    return phase + max(1, (now_ms - phase) // period + 1) * period


def next_tick(due: int, period: int, phase: int, now_ms: int) -> int:
    """The tick after the one due at `due` that left the timer queue at `now_ms`: one
    period later, or, when that is a period or more past, the first tick after `now_ms`
    (the missed periods are skipped)."""
    after = due + period
    if after + period <= now_ms:
        return first_tick(period, phase, now_ms)
    return after


def next_ticks(due: int, period: int, phase: int, lateness: tuple[int, int]
               ) -> tuple[tuple[int, int], ...]:
    """Every next tick (`next_tick`) of a tick due at `due` that leaves the queue
    `lateness` (min, max) ms late, in increasing order, each with the least lateness
    that gives it: ((next tick, least lateness), ...)."""
    low, high = lateness
    out = [(next_tick(due, period, phase, due + low), low)]
    # Ticks change only where the lateness crosses a grid point; step from one to the next.
    late = max(low, 2 * period)
    while late <= high:
        tick = next_tick(due, period, phase, due + late)
        if tick != out[-1][0]:
            out.append((tick, late))
        late = tick - due  # the lateness at which the tick after this one takes over
    return tuple(out)


def keep_last_depth(depth: int) -> int:
    """How many waiting messages a KEEP_LAST subscription declared with `depth` holds."""
    return max(1, depth)


def keep_last_excess(waiting: int, depth: int) -> int:
    """How many of the oldest waiting messages KEEP_LAST drops when a subscription that
    holds `depth` (`keep_last_depth`) has `waiting` (the newest included)."""
    return max(0, waiting - depth)
