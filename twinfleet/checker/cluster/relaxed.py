"""A relaxed-order search driven from the coordinator (`checker.cluster.flow`): the
workers expand without levels; the coordinator only reads their counters, ends the
search when they are all idle with every claim answered twice in a row, and walks a
counterexample once they stopped (they would slow every call).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

from twinfleet.checker.cluster.backend import Placement, Traffic
from twinfleet.checker.cluster.flow import FlowBackend, FlowStatus
from twinfleet.checker.cluster.level import visited_from
from twinfleet.checker.cluster.spec import ClusterError
from twinfleet.checker.cluster.tally import Tally
from twinfleet.checker.outcome import Limits, Stop

POLL_S = 0.05  # the coordinator reads the workers this often
# Up to this many states (16 bytes each), a counterexample is walked on every partition
# fetched at once rather than asked of the partitions step by step (`whole_lineage`).
DUMP_STATES = 4_000_000


def run_relaxed(flow: FlowBackend, tally: Tally, traffic: Traffic, limits: Limits,
                tick: Callable[[], None]) -> list[FlowStatus]:
    """Let the workers search to the end or to a find and stop them; their last statuses.
    `tick` runs between two reads (Ctrl-C, max-time, the progress line)."""
    before = (tally.states, tally.transitions)
    quiet: list[tuple[int, int]] | None = None
    try:
        while True:
            flow.advance(POLL_S)
            statuses = flow.status()
            tally.add_flow(statuses, before, traffic)
            if any(s.failure is not None or s.violation is not None for s in statuses):
                break
            if limits.max_states is not None and tally.states >= limits.max_states:
                raise Stop(f"max-states {limits.max_states} reached before the search finished")
            counts = [(s.sent, s.received) for s in statuses]
            if all(s.idle for s in statuses) and \
                    sum(s.sent for s in statuses) == sum(s.received for s in statuses):
                if counts == quiet:  # nothing moved between two reads: the end
                    break
                quiet = counts
            else:
                quiet = None
            tick()
    finally:
        flow.stop()
    return statuses


def whole_lineage(flow: FlowBackend, states: int, roots: Mapping[int, tuple[int, ...]]
                  ) -> Callable[[int], list[int]] | None:
    """A key's parent on the whole visited set, fetched here in one call per partition,
    when the search kept at most `DUMP_STATES` (a path over two workers changes partition
    at about every other step, each change a round trip: the crossing fleet's 615-step path
    took 0.26-0.29 s walked so, 0.14-0.16 s fetched whole, the fetch 30 ms of it); None:
    too many, ask the partitions instead."""
    if states > DUMP_STATES:
        return None
    whole = visited_from(flow.visited(), dict(roots))

    def parent(key: int) -> list[int]:
        found = whole.get(key)
        if found is None:
            raise ClusterError(f"the workers' visited sets lack a key of the path: {key}")
        return [found]
    return parent


def ancestry(place: Placement, states: int, roots: Mapping[int, tuple[int, ...]]
             ) -> Callable[[int], list[int]]:
    """How `walk.walk` finds a key's ancestors: after a relaxed order, on the whole visited
    set if it is small enough (`whole_lineage`); else one call per change of partition."""
    whole = None if place.flow is None else whole_lineage(place.flow, states, roots)
    return place.lineage if whole is None else whole
