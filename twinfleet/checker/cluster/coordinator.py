"""The distributed search's coordinator: strict BFS level by level over a `Backend`.

The search starts in this process (`LocalBackend`: one expander, one shard).
When a level's frontier reaches `min_width` worlds and more than one process
was asked for, the cluster's workers start (`checker.cluster.engine.RayBackend`)
while the search goes on here, and once they are up the frontier and the visited
set are handed to them and the search goes on there; a search
whose frontier never gets that wide ends here and says so, since a per-level
barrier (about a millisecond of round trips) is ruinous against a level of a
few worlds. For the same reason a search whose frontier stays narrower than
`min_width` for `patience` levels comes back here, frontier and
visited set, until it widens again (the workers keep what they recorded of
the graph); a move costs time in proportion to the visited set, so each return
doubles the patience the next one needs (`checker.cluster.backend.Placement` decides where
each level runs). Every level ends with a barrier, so the search is a strict BFS:
the same states, transitions and depth as `checker.search` for any number of
workers, and a counterexample of the same length. After each level the
coordinator moves frontier worlds from the busiest worker to the idlest when
they differ by more than `STEAL_MIN` (one packed blob per move).

A reduced search (`checker.reduction`) runs the same levels in two halves
(`Expander.propose`, then `expand`) and learns its send relation level by
level (`Publications.freeze`): when some worker learned a send, the
coordinator merges what every worker learned and starts the search again
from scratch with it, as the search in one process does at the end of that
level, so both explore the same reduced graph.

Between two levels the search is consistent, so that is where it stops on
Ctrl-C, max-time or max-states, and where it is saved (`Checkpointing`): the
visited set and every worker's frontier gathered into one
`checker.checkpoint` file, which `Coordinator.restore` continues on any
number of workers, this process included.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from functools import partial
from typing import Any, cast, final

from twinfleet.checker import checkpoint as ckpt
from twinfleet.checker.cluster.backend import (
    Checkpointing,
    Factory,
    FlowFactory,
    Placement,
    Traffic,
    balance,
)
from twinfleet.checker.cluster.level import (
    ROOT,
    Failure,
    Learned,
    visited_from,
)
from twinfleet.checker.cluster.relaxed import ancestry, run_relaxed
from twinfleet.checker.cluster.saving import (
    add_learned_counts,
    counters,
    relearn,
    restored_tally,
    take_frontier,
)
from twinfleet.checker.cluster.spec import ClusterError
from twinfleet.checker.cluster.tally import Tally
from twinfleet.checker.cluster.walk import failing_step, first_lasso, gathered, walk
from twinfleet.checker.late_start import Start, start
from twinfleet.checker.outcome import (
    INTERRUPTED_REASON,
    Counterexample,
    Guard,
    Limits,
    Outcome,
    SearchStatistics,
    Stop,
)
from twinfleet.checker.properties import PropertySet, PropertyViolation
from twinfleet.checker.reduction import Reduction
from twinfleet.checker.system import System
from twinfleet.runtime.contract.kinds import Status

# A search smaller than this is over in a few seconds in one process: less than a local
# cluster takes to start (3-15 s here), and the cluster's processes hold about a gigabyte.
START_STATES = 50_000
PATIENCE = 16  # narrow levels in a row before the first return (doubled after each)
ENGINE = "cluster"  # a checkpoint's meta["engine"]: written by this coordinator


@final
class Coordinator:
    """One distributed strict-BFS search (module docstring).

    Args:
        system, properties: the coordinator's own copy (initial worlds, counterexamples).
        limits: as `checker.search.Search` takes them (checked between levels).
        factory: starts the cluster's backend (once: a restart reuses it) and returns
            at once; the search goes on here until the backend is `ready`. None:
            everything in this process.
        min_width: frontier width at which the search moves to the cluster.
        report: called with a progress line at most every `interval` seconds.
        checkpointing: save the search between levels (periodically and when it stops
            early), or None.
        reduction: the partial-order reduction of the coordinator's system, or None.
        back_width: a frontier narrower than this comes back (default min_width).
        patience: narrow levels in a row before the first return.
        start_states: the cluster starts only once the search found this many states
            (and a level is `min_width` wide).
        flow: starts the workers of a relaxed order (`checker.cluster.flow`), as
            `factory` does, which then replace `factory`'s levels; None: a strict BFS.
            Only for a search without reduction, depth bound or checkpoints.
    """

    def __init__(self, system: System, properties: PropertySet, limits: Limits,
                 factory: Factory | None, min_width: int,
                 report: Callable[[str], None] | None = None, interval: float = 1.0,
                 checkpointing: Checkpointing | None = None,
                 reduction: Reduction | None = None, back_width: int | None = None,
                 patience: int = PATIENCE, flow: FlowFactory | None = None,
                 start_states: int = 0) -> None:
        if flow is not None and (reduction is not None or limits.max_depth is not None
                                 or checkpointing is not None):
            raise ValueError("a relaxed order needs a search without reduction, depth bound "
                             "or checkpoints")
        self.system, self.properties, self.limits = system, properties, limits
        self.report, self.interval = report, interval
        self.checkpointing = checkpointing
        self.reduction = reduction
        if reduction is not None:
            reduction.freeze()
            reduction.begin()
        self.guard = Guard(limits, None, interval, handle_sigint=True)
        self.place = Placement(system, properties, reduction, factory, flow,
                               min_width=min_width,
                               back_width=min_width if back_width is None else back_width,
                               patience=patience, tick=partial(self.guard.tick, self.statistics),
                               report=report, start_states=start_states,
                               tick_within_levels=checkpointing is None)
        self.roots: dict[int, tuple[int, ...]] = {}
        self.traffic = Traffic()
        self.tally = Tally()
        self._last_report = self._last_save = time.monotonic()
        self._elapsed_before = 0.0  # the time of the runs a restored checkpoint continues
        self._restored = False
        self._attempt: float | None = None  # when the search last started again (monotonic)
        self.saved: str | None = None  # the checkpoint file, once written

    # ------------------------------------------------------------------ run

    def run(self) -> Outcome:
        """Search to a verdict or a limit (Ctrl-C, max-time and max-states stop it between
        two levels; a second Ctrl-C at once)."""
        self.guard.restart_clock()
        self._last_report = self._last_save = self.guard.started
        with self.guard.sigint_handler():
            try:
                return self._search()
            except Stop as stop:
                if self.checkpointing is not None:
                    self.save()
                return self._outcome(Status.UNKNOWN, stop.reason)
            except KeyboardInterrupt:  # a second Ctrl-C, maybe inside a level
                return self._outcome(Status.UNKNOWN, INTERRUPTED_REASON)
            except ClusterError as exc:
                if self.saved is None:
                    raise
                raise ClusterError(f"{exc}; the search saved before continues with: "
                                   f"twinfleet check --resume {self.saved}") from None

    def _search(self) -> Outcome:
        if not self._restored:
            found = self._start()
            if found is not None:
                return found
        while self.tally.frontier:
            if self._probed():
                found = self._start()
                if found is not None:
                    return found
                continue
            waits = self.reduction is not None and self.reduction.waiting and \
                self.reduction.aside is None  # it decides on a sample of the frontier here
            if not waits and self.place.before_level(self.tally.frontier, self.tally.level,
                                                     self.roots, self.traffic, self.tally.states):
                return self._flow()
            outcome = self._level()
            if outcome is not None:
                return outcome
            self._maybe_save()
        if self.properties.eventually:
            return self._liveness()
        return self._outcome(Status.HOLDS, "every property holds")

    def _probed(self) -> bool:
        """Start the reduction that waits (`checker.late_start`), or walk ahead once the
        search is large, at the level the one-process search does (`Reduction.probe`);
        True if the search starts again from scratch."""
        reduction = self.reduction
        if reduction is not None and reduction.waiting:  # (stays so if it steps aside)
            frontier = (w for w, _, _ in self.place.local.expander.frontier)  # here till then
            if start(reduction, self.tally.states, frontier) is not Start.REDUCE:
                return False
            self._restart([], counted=False)
            return True
        if reduction is None or not reduction.probe(self.tally.states, self.limits.max_depth) \
                or not reduction.stale:
            return False
        self._restart([])
        return True

    def _restart(self, learned: list[Learned], counted: bool = True) -> None:
        """Some worker learned a send: merge what all learned and search from scratch
        (`counted`: as a restart)."""
        reduction = self.reduction
        assert reduction is not None
        self._merge(learned)
        if counted:
            reduction.restarted()
        reduction.begin()
        self.place.restart()
        self.roots = {}
        self.tally = Tally()
        self._attempt = time.monotonic()

    def _merge(self, learned: list[Learned]) -> None:
        """Add what the workers learned to the relation."""
        assert self.reduction is not None
        for found in learned:
            self.reduction.publications.commit(found.edges, found.unknown)
            self.reduction.visibility.commit(found.fell)

    def _start(self) -> Outcome | None:
        """The initial worlds, claimed and checked here."""
        shard, frontier = self.place.local.shard, self.place.local.expander.frontier
        for t in self.system.initial():
            self.tally.initial += 1
            if t.failure is not None:
                return self._violated(self.properties.check_failure(t.failure),
                                      Counterexample(t.step.choices, ()))
            key = cast(int, t.world.key)
            if key in shard.visited:
                continue
            shard.visited.put(key, ROOT)
            self.roots[key] = t.step.choices
            self.tally.states += 1
            if self.place.local.expander.graph is not None:
                self.place.local.expander.graph.keep(self.system, self.properties, t.world, key)
            violation = self.properties.check_world(self.system, t.world)
            if violation is not None:
                return self._violated(violation, Counterexample(t.step.choices, ()))
            frontier.append((t.world, key, 0))
        self.tally.frontier = self.tally.peak_frontier = len(frontier)
        return None

    def _level(self) -> Outcome | None:
        expansions, acceptances = self.place.backend.level(self.limits.max_depth)
        self.tally.add_level(expansions, acceptances, self.traffic,
                             remote=self.place.backend is not self.place.local)
        found = self._found([e.failure for e in expansions], [a.violation for a in acceptances])
        if found is not None:
            return found
        learned = [a.learned for a in acceptances if a.learned is not None]
        if self.place.backend is not self.place.local:
            add_learned_counts(self.reduction, learned)
        if any(found.grew() for found in learned):
            if self.reduction is not None and self.reduction.waiting:
                self._merge(learned)  # in place: no world relied on the relation yet
            else:
                self._restart(learned)
                return self._start()
        if any(e.pruned for e in expansions) and not self.tally.frontier:
            return self._outcome(Status.UNKNOWN, f"max-depth {self.limits.max_depth} "
                                 "reached before the search finished")
        balance(self.place.backend, [a.frontier for a in acceptances], self.traffic)
        if self.limits.max_states is not None and self.tally.states >= self.limits.max_states:
            raise Stop(f"max-states {self.limits.max_states} reached before the search finished")
        self._tick()
        return None

    def _tick(self) -> None:
        self.guard.tick(self.statistics)  # Ctrl-C, max-time
        self._progress()

    # ------------------------------------------------------------ relaxed order

    def _flow(self) -> Outcome:
        """The rest of the search on workers that do not wait for each other
        (`checker.cluster.flow`), to its end: no level, no return to this process."""
        flow = self.place.to_flow(self.tally.level)
        statuses = run_relaxed(flow, self.tally, self.traffic, self.limits, self._tick)
        # The path is walked once the workers stopped: they would slow every call.
        found = self._found([s.failure for s in statuses], [s.violation for s in statuses])
        if found is not None:
            return found
        if self.properties.eventually:
            return self._liveness()
        return self._outcome(Status.HOLDS, "every property holds")

    # ------------------------------------------------------------- liveness

    def _liveness(self) -> Outcome:
        """Every `eventually` property, by the lasso search of one process, on the graph
        the workers saw, gathered here (`checker.paths`)."""
        found = first_lasso(self.system, gathered(*self.place.graph(), self.roots,
                                                  self.properties), self.properties)
        if found is not None:
            return self._violated(*found)
        return self._outcome(Status.HOLDS, "every property holds")

    # ------------------------------------------------------------- answers

    def statistics(self) -> SearchStatistics:
        """The counters so far."""
        attempt = None if self._attempt is None else time.monotonic() - self._attempt
        return self.tally.statistics(self._elapsed(), self.place.current.shard_bytes(), attempt)

    def _elapsed(self) -> float:
        return self._elapsed_before + time.monotonic() - self.guard.started

    def _outcome(self, status: Status, reason: str) -> Outcome:
        outcome = Outcome(status, reason, self.statistics())
        if status is Status.UNKNOWN:
            outcome.checkpoint = self.saved
        return outcome

    # --------------------------------------------------------- checkpoints

    def _maybe_save(self) -> None:
        plan = self.checkpointing
        if plan is not None and time.monotonic() - self._last_save >= plan.every_s:
            self.save()

    def save(self) -> str:
        """Write the search as it stands between two levels to the checkpoint file."""
        plan = self.checkpointing
        assert plan is not None
        frontier, visited = self.place.backend.snapshot()
        counted = counters(self.tally, self.traffic, self.roots, self.place.distributed_at,
                           self._elapsed(), self.reduction)
        ckpt.save(plan.path, {**plan.meta, "engine": ENGINE}, {"visited": visited}, frontier,
                  counted)
        self._last_save = time.monotonic()
        self.saved = plan.path
        return plan.path

    def restore(self, data: Mapping[str, Any]) -> None:
        """Continue a checkpoint `save` wrote (`checker.checkpoint.load`), on this process
        until the frontier is `min_width` wide, whatever number of workers wrote it."""
        c = data["counters"]
        self.tally = restored_tally(c)
        self._elapsed_before, self.roots = c["elapsed"], c["roots"]
        self.traffic = Traffic(**c["traffic"])
        relearn(self.reduction, c)
        self.place.local.shard.visited = visited_from(data["store"]["visited"], self.roots)
        take_frontier(self.place.local.expander, data["frontier"])
        self.tally.frontier = len(self.place.local.expander.frontier)
        self._restored = True

    def _found(self, failures: list[Failure | None],
               violations: list[tuple[PropertyViolation, int, int] | None]) -> Outcome | None:
        """The outcome of the first handler failure, else the first violation, the workers
        met (a failure's parent, a violating world's key), or None."""
        failure = next((f for f in failures if f is not None), None)
        if failure is not None:  # the first failing step from the failure's parent
            path, world = walk(self.system, self.roots, self._ancestry(), failure.parent)
            return self._violated(*failing_step(self.system, self.properties, path, world))
        violation = next((v for v in violations if v is not None), None)
        if violation is not None:
            return self._violated(violation[0],
                                  walk(self.system, self.roots, self._ancestry(), violation[1])[0])
        return None

    def _violated(self, violation: PropertyViolation, path: Counterexample) -> Outcome:
        return Outcome(Status.VIOLATED, violation.property, self.statistics(), violation, path)

    def _ancestry(self) -> Callable[[int], list[int]]:
        return ancestry(self.place, self.tally.states, self.roots)

    def _progress(self) -> None:
        now = time.monotonic()
        if self.report is None or now - self._last_report < self.interval:
            return
        self._last_report = now
        place = self.place
        where = "in this process" if place.current is place.local else \
            f"{place.current.workers} worker(s)"
        shards = self.place.current.shard_bytes()
        self.report(self.tally.progress_line(where, self.traffic, shards, self._elapsed()))
