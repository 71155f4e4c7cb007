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
doubles the patience the next one needs. Every level ends with a barrier, so the search is a strict BFS:
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

import dataclasses
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol, cast, final

from twinfleet.checker import checkpoint as ckpt
from twinfleet.checker.cluster.flow import FlowBackend, FlowStatus
from twinfleet.checker.cluster.level import (
    ROOT,
    Acceptance,
    Expander,
    Expansion,
    Failure,
    Graph,
    Item,
    Learned,
    ShardCore,
    unpack,
    visited_from,
)
from twinfleet.checker.cluster.spec import ClusterError
from twinfleet.checker.cluster.visited import VisitedTable
from twinfleet.checker.diagnosis import FIX_HIDDEN, ContractBreachError, breach_line
from twinfleet.checker.outcome import (
    INTERRUPTED_REASON,
    Counterexample,
    Guard,
    Limits,
    Outcome,
    SearchStatistics,
    Stop,
    peak_rss_mb,
)
from twinfleet.checker.paths import lasso_counterexample
from twinfleet.checker.properties import PropertySet, PropertyViolation
from twinfleet.checker.reduction import Reduction, ReductionStatistics
from twinfleet.checker.store import StateStore
from twinfleet.checker.system import System
from twinfleet.checker.world import World
from twinfleet.runtime.contract.kinds import FailureKind, Status

STEAL_MIN = 64  # frontier worlds two workers must differ by before some are moved
POLL_S = 0.05  # a relaxed-order search's coordinator reads the workers this often
START_POLL_S = 0.01  # how often a search that waits for its workers asks if they are up
# Up to this many states (16 bytes each), a relaxed-order search's counterexample is
# walked on every partition fetched at once rather than asked of the partitions step
# by step (`_ancestry`).
DUMP_STATES = 4_000_000
PATIENCE = 16  # narrow levels in a row before the first return (doubled after each)
ENGINE = "cluster"  # a checkpoint's meta["engine"]: written by this coordinator


class Backend(Protocol):
    """Where levels are expanded: this process, or a cluster of workers and shards."""

    workers: int

    def ready(self) -> bool:
        """Whether every worker is up (raises ClusterError if one cannot start)."""
        ...

    def level(self, max_depth: int | None) -> tuple[list[Expansion], list[Acceptance]]:
        """Expand every worker's frontier by one level; claims answered, new worlds kept."""
        ...

    def lineage(self, key: int) -> list[int]:
        """The parent of a visited key and its ancestors, one call's worth
        (`ShardCore.lineage`): ends with ROOT or with a key to ask about next."""
        ...

    def shard_bytes(self) -> list[int]:
        """Bytes held per shard."""
        ...

    def move(self, source: int, target: int, count: int) -> None:
        """Move `count` frontier worlds from worker `source` to worker `target`."""
        ...

    def snapshot(self) -> tuple[list[bytes], list[bytes]]:
        """Every worker's frontier (`Expander.packed`) and every shard's visited keys
        (`ShardCore.dump`), between two levels."""
        ...

    def load(self, frontier: list[Item], visited: VisitedTable,
             relation: tuple[Any, ...] | None) -> None:
        """Take over a search begun in the coordinator: its frontier, its visited set and
        (reduced) the send relation learned so far."""
        ...

    def reset(self, relation: tuple[Any, ...] | None) -> None:
        """Forget the search (a reduced search starts again with `relation`)."""
        ...

    def graphs(self) -> list[Graph]:
        """What every worker saw of the graph (`eventually` properties), at the end."""
        ...

    def take_back(self) -> tuple[list[Item], list[bytes]]:
        """Every worker's frontier and every shard's visited keys (`ShardCore.dump`),
        leaving them empty (the search goes on in the coordinator)."""
        ...


@final
class LocalBackend:
    """One expander and one shard in this process."""

    workers = 1

    def __init__(self, system: System, properties: PropertySet,
                 reduction: Reduction | None = None) -> None:
        self.expander = Expander(system, properties, 1, reduction)
        self.shard = ShardCore()
        self._fresh = True  # used as a cluster: the coordinator's relation not learned yet

    def ready(self) -> bool:
        """Always (`Backend.ready`)."""
        return True

    def level(self, max_depth: int | None) -> tuple[list[Expansion], list[Acceptance]]:
        """One level here (`Backend.level`)."""
        stored = None
        if self.expander.reduction is not None:
            stored = self.shard.stored(self.expander.propose(max_depth))
        expansion, blobs = self.expander.expand(max_depth, stored)
        return [expansion], [self.expander.accept(self.shard.claim(blobs))]

    def lineage(self, key: int) -> list[int]:
        """`Backend.lineage`: all of it (one partition)."""
        return self.shard.lineage(key, 0, 1)

    def shard_bytes(self) -> list[int]:
        """`Backend.shard_bytes`."""
        return [self.shard.nbytes()]

    def move(self, source: int, target: int, count: int) -> None:
        """Nothing to move between one worker."""

    def snapshot(self) -> tuple[list[bytes], list[bytes]]:
        """`Backend.snapshot`."""
        return [self.expander.packed()], [self.shard.dump()]

    def load(self, frontier: list[Item], visited: VisitedTable,
             relation: tuple[Any, ...] | None) -> None:
        """`Backend.load`, as a cluster of one worker does it (the coordinator's own
        backend is never loaded; a stand-in cluster in tests is)."""
        if relation is not None and self._fresh:  # later loads: the same relation
            self.expander.relearn(relation)
        self._fresh = False
        self.expander.frontier += frontier
        self.shard.add(*visited.arrays())

    def reset(self, relation: tuple[Any, ...] | None) -> None:
        """`Backend.reset` (the coordinator makes a new local backend instead)."""
        if relation is None:
            self.expander.frontier = []
        else:
            self.expander.relearn(relation)
        self.shard.clear()
        self._fresh = False

    def graphs(self) -> list[Graph]:
        """`Backend.graphs`."""
        return [] if self.expander.graph is None else [self.expander.graph]

    def take_back(self) -> tuple[list[Item], list[bytes]]:
        """`Backend.take_back`, as a cluster of one worker does it."""
        frontier, self.expander.frontier = self.expander.frontier, []
        return frontier, [self.shard.drain()]


@final
@dataclass
class Traffic:
    """What crossed between processes (for the benchmark and the progress line)."""

    claims: int = 0  # (key, parent) pairs sent to shards
    stolen: int = 0  # frontier worlds moved between workers
    moves: int = 0  # blobs moved
    levels: int = 0  # barriers
    returns: int = 0  # times a narrowing search came back to the coordinator
    new_per_worker: list[int] = field(default_factory=list)
    handler_runs: list[int] = field(default_factory=list)  # per worker, so far


Factory = Callable[[int], Backend]  # the cluster's backend, started empty (the frontier's width)
FlowFactory = Callable[[int], FlowBackend]  # the same for a relaxed order


@final
@dataclass(frozen=True)
class Checkpointing:
    """Where a distributed search is saved, how often, and what the file records of the
    check (`checker.checkpoint` meta: scenario, its hash, options)."""

    path: str
    every_s: float
    meta: Mapping[str, Any]


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
        flow: starts the workers of a relaxed order (`checker.cluster.flow`), as
            `factory` does, which then replace `factory`'s levels; None: a strict BFS.
            Only for a search without reduction, depth bound or checkpoints.
    """

    def __init__(self, system: System, properties: PropertySet, limits: Limits,
                 factory: Factory | None, min_width: int,
                 report: Callable[[str], None] | None = None, interval: float = 1.0,
                 checkpointing: Checkpointing | None = None,
                 reduction: Reduction | None = None, back_width: int | None = None,
                 patience: int = PATIENCE, flow: FlowFactory | None = None) -> None:
        if flow is not None and (reduction is not None or limits.max_depth is not None
                                 or checkpointing is not None):
            raise ValueError("a relaxed order needs a search without reduction, depth bound "
                             "or checkpoints")
        self.system, self.properties, self.limits = system, properties, limits
        self.factory, self.min_width = factory, min_width
        self.back_width = min_width if back_width is None else back_width
        self.patience, self._narrow = patience, 0
        self.report, self.interval = report, interval
        self.checkpointing = checkpointing
        self.reduction = reduction
        if reduction is not None:
            reduction.freeze()
            reduction.begin()
        self.guard = Guard(limits, None, interval, handle_sigint=True)
        self.local = LocalBackend(system, properties, reduction)
        self.backend: Backend = self.local
        self.cluster: Backend | None = None
        self.flow_factory = flow
        self.flow: FlowBackend | None = None  # the relaxed order's workers, once searching
        self._starting: Backend | FlowBackend | None = None  # the cluster's, once started
        self.roots: dict[int, tuple[int, ...]] = {}
        self.traffic = Traffic()
        self.states = self.transitions = self.initial = self.depth = self.frontier = 0
        self.peak_frontier = self.level = 0
        self.distributed_at: int | None = None  # the level where the cluster took over
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
        while self.frontier:
            if self._probed():
                found = self._start()
                if found is not None:
                    return found
                continue
            if self.backend is self.local and self.factory is not None and \
                    self.frontier >= self.min_width and self._started():
                if self.flow_factory is not None:
                    return self._flow()
                self._to_cluster()
            elif self.backend is not self.local:
                self._narrow = self._narrow + 1 if self.frontier < self.back_width else 0
                if self._narrow >= self.patience << self.traffic.returns:
                    self._to_local()
            outcome = self._level()
            if outcome is not None:
                return outcome
            self._maybe_save()
        if self.properties.eventually:
            return self._liveness()
        return self._outcome(Status.HOLDS, "every property holds")

    def _probed(self) -> bool:
        """Walk ahead once the search is large, at the level the one-process search does
        (`Reduction.probe`); True if that learned something and the search restarted."""
        reduction = self.reduction
        if reduction is None or not reduction.probe(self.states, self.limits.max_depth) or \
                not reduction.stale:
            return False
        self._restart([])
        return True

    def _started(self) -> bool:
        """Start the cluster's backend, once, and say whether its workers are up. They
        start while the search goes on here (a worker process takes a second or two to
        import the node code and build its system: time this process spends searching),
        except with `min_width` 1, which asks for the whole search on the workers: then
        this waits for them."""
        if self._starting is None:
            if self.flow_factory is not None:
                self._starting = self.flow_factory(self.frontier)
            else:
                assert self.factory is not None
                self._starting = self.factory(self.frontier)
        while not self._starting.ready():
            if self.min_width > 1:
                return False
            self.guard.tick(self.statistics)  # Ctrl-C, max-time
            time.sleep(START_POLL_S)
        if self.report is not None and self.distributed_at is None:
            self.report(f"[check] {self._starting.workers} worker(s) up: the search moves "
                        f"to them at depth {self.level}, frontier {self.frontier:,} wide")
        return True

    def _to_cluster(self) -> None:
        """Hand the frontier and the visited set to the cluster's backend."""
        self.cluster = cast(Backend, self._starting)
        self.cluster.load(self.local.expander.frontier, self.local.shard.visited,
                          self._relation())
        self.local.expander.frontier = []
        self.backend = self.cluster
        if self.distributed_at is None:
            self.distributed_at = self.level

    def _to_local(self) -> None:
        """Take the frontier and the visited set back from the cluster."""
        frontier, visited = self.backend.take_back()
        self.local.expander.frontier = frontier
        self.local.shard.visited = visited_from(visited, self.roots)
        self.backend = self.local
        self.traffic.returns += 1
        self._narrow = 0

    def _relation(self) -> tuple[Any, ...] | None:
        return None if self.reduction is None else self.reduction.learned_state()

    def _restart(self, learned: list[Learned]) -> None:
        """Some worker learned a send: merge what all learned and search from scratch."""
        reduction = self.reduction
        assert reduction is not None
        for found in learned:
            reduction.publications.commit(found.edges, found.unknown)
            reduction.visibility.commit(found.fell)
        reduction.restarted()
        reduction.begin()
        if self.cluster is not None:
            self.cluster.reset(self._relation())
        self.local = LocalBackend(self.system, self.properties, reduction)
        self.backend = self.local
        self.roots = {}
        self.states = self.transitions = self.initial = self.depth = self.frontier = 0
        self.peak_frontier = self.level = 0
        self._attempt = time.monotonic()

    def _start(self) -> Outcome | None:
        """The initial worlds, claimed and checked here."""
        shard, frontier = self.local.shard, self.local.expander.frontier
        for t in self.system.initial():
            self.initial += 1
            if t.failure is not None:
                return self._violated(self.properties.check_failure(t.failure),
                                      Counterexample(t.step.choices, ()))
            key = cast(int, t.world.key)
            if key in shard.visited:
                continue
            shard.visited.put(key, ROOT)
            self.roots[key] = t.step.choices
            self.states += 1
            if self.local.expander.graph is not None:
                self.local.expander.graph.keep(self.system, self.properties, t.world, key)
            violation = self.properties.check_world(self.system, t.world)
            if violation is not None:
                return self._violated(violation, Counterexample(t.step.choices, ()))
            frontier.append((t.world, key, 0))
        self.frontier = self.peak_frontier = len(frontier)
        return None

    def _level(self) -> Outcome | None:
        expansions, acceptances = self.backend.level(self.limits.max_depth)
        t = self.traffic
        t.levels += 1
        self.level += 1
        t.claims += sum(e.claims for e in expansions) if self.backend is not self.local else 0
        if len(t.new_per_worker) < len(acceptances):
            t.new_per_worker = [0] * len(acceptances)
        if self.backend is not self.local:
            t.handler_runs = [a.handler_runs for a in acceptances]
        self.transitions += sum(e.transitions for e in expansions)
        for i, a in enumerate(acceptances):
            self.states += a.new
            t.new_per_worker[i] += a.new
            self.depth = max(self.depth, a.depth)
        self.frontier = sum(a.frontier for a in acceptances)
        self.peak_frontier = max(self.peak_frontier, self.frontier)
        found = self._found([e.failure for e in expansions], [a.violation for a in acceptances])
        if found is not None:
            return found
        learned = [a.learned for a in acceptances if a.learned is not None]
        if self.backend is not self.local:
            self._count(learned)
        if any(found.grew() for found in learned):
            self._restart(learned)
            return self._start()
        if any(e.pruned for e in expansions) and not self.frontier:
            return self._outcome(Status.UNKNOWN, f"max-depth {self.limits.max_depth} "
                                 "reached before the search finished")
        self._balance([a.frontier for a in acceptances])
        if self.limits.max_states is not None and self.states >= self.limits.max_states:
            raise Stop(f"max-states {self.limits.max_states} reached before the search finished")
        self.guard.tick(self.statistics)  # Ctrl-C, max-time
        self._progress()
        return None

    def _balance(self, sizes: list[int]) -> None:
        """Move worlds from the busiest worker to the idlest (work sharing)."""
        if len(sizes) < 2:
            return
        busy = max(range(len(sizes)), key=sizes.__getitem__)
        idle = min(range(len(sizes)), key=sizes.__getitem__)
        gap = sizes[busy] - sizes[idle]
        if gap > STEAL_MIN:
            self.backend.move(busy, idle, gap // 2)
            self.traffic.stolen += gap // 2
            self.traffic.moves += 1

    # ------------------------------------------------------------ relaxed order

    def _flow(self) -> Outcome:
        """The rest of the search on workers that do not wait for each other
        (`checker.cluster.flow`), to its end: no level, no return to this process."""
        flow = self.flow = cast(FlowBackend, self._starting)
        self.distributed_at = self.level
        flow.load(self.local.expander.frontier, self.local.shard.visited)
        self.local.expander.frontier = []
        before = (self.states, self.transitions)
        quiet: list[tuple[int, int]] | None = None
        try:
            while True:
                flow.advance(POLL_S)
                statuses = flow.status()
                if self._flowed(statuses, *before):
                    break
                counts = [(s.sent, s.received) for s in statuses]
                if all(s.idle for s in statuses) and \
                        sum(s.sent for s in statuses) == sum(s.received for s in statuses):
                    if counts == quiet:  # nothing moved between two reads: the end
                        break
                    quiet = counts
                else:
                    quiet = None
                self.guard.tick(self.statistics)  # Ctrl-C, max-time
                self._progress()
        finally:
            flow.stop()
        # The path is walked once the workers stopped: they would slow every call.
        found = self._found([s.failure for s in statuses], [s.violation for s in statuses])
        if found is not None:
            return found
        if self.properties.eventually:
            return self._liveness()
        return self._outcome(Status.HOLDS, "every property holds")

    def _flowed(self, statuses: list[FlowStatus], states: int, transitions: int) -> bool:
        """Count what the workers did; whether one found a violation or a failure."""
        t = self.traffic
        self.states = states + sum(s.new for s in statuses)
        self.transitions = transitions + sum(s.transitions for s in statuses)
        self.depth = max(self.depth, *(s.depth for s in statuses))
        self.frontier = sum(s.queue for s in statuses)
        self.peak_frontier = max(self.peak_frontier, self.frontier)
        t.claims = sum(s.claims for s in statuses)
        t.new_per_worker = [s.new for s in statuses]
        t.stolen, t.moves = sum(s.gifted for s in statuses), sum(s.gifts for s in statuses)
        t.handler_runs = [s.handler_runs for s in statuses]
        if any(s.failure is not None or s.violation is not None for s in statuses):
            return True
        if self.limits.max_states is not None and self.states >= self.limits.max_states:
            raise Stop(f"max-states {self.limits.max_states} reached before the search finished")
        return False

    # ------------------------------------------------------------- liveness

    def _liveness(self) -> Outcome:
        """Every `eventually` property, by the lasso search of one process, on the graph
        the workers saw, gathered here (`checker.paths`)."""
        store = self._gathered()
        for prop in self.properties.eventually:
            found = lasso_counterexample(self.system, store, prop)
            if found is not None:
                return self._violated(*found)
        return self._outcome(Status.HOLDS, "every property holds")

    def _gathered(self) -> StateStore:
        """The whole graph as a one-process search records it: ids, first-discovery
        parents, roots, terminal worlds, the properties' bits and the successor ids."""
        graph = Graph()
        remote = self.flow if self.flow is not None else self.cluster
        for part in (*self.local.graphs(), *(() if remote is None else remote.graphs())):
            graph.extend(part)
        if self.flow is not None:
            visited = self.flow.visited()
        elif self.backend is self.local:
            visited = [self.local.shard.dump()]
        else:
            visited = self.backend.snapshot()[1]
        store = graph.store(visited, self.roots, tuple(p.name for p in self.properties.eventually))
        for key, choices in self.roots.items():
            store.roots[store.find(key)] = choices
        return store

    # ------------------------------------------------------------- answers

    def statistics(self) -> SearchStatistics:
        """The counters so far."""
        n = self.states
        return SearchStatistics(n, self.transitions, self.initial, self.depth, self.frontier,
                                self._elapsed(), peak_rss_mb(),
                                sum(self._shard_bytes()), 64, min(1.0, n * n / 2.0**65),
                                self.peak_frontier,
                                None if self._attempt is None else time.monotonic() - self._attempt)

    def _shard_bytes(self) -> list[int]:
        return (self.flow or self.backend).shard_bytes()

    def _count(self, learned: list[Learned]) -> None:
        """Add the workers' reduction counters to this process's (the summary's)."""
        if self.reduction is None:
            return
        stats = self.reduction.stats
        for found in learned:
            counted = dict(found.counted)
            self.reduction.visibility.rises += counted.pop("rises", 0)
            for name, value in counted.items():
                setattr(stats, name, getattr(stats, name) + value)
            self.reduction.relied |= found.relied

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
        frontier, visited = self.backend.snapshot()
        counters = {"states": self.states, "transitions": self.transitions,
                    "initial": self.initial, "depth": self.depth,
                    "peak_frontier": self.peak_frontier, "level": self.level,
                    "distributed_at": self.distributed_at, "elapsed": self._elapsed(),
                    "roots": self.roots, "traffic": dataclasses.asdict(self.traffic),
                    "publications": self._relation(),
                    "reduction": None if self.reduction is None else
                    self.reduction.statistics(),
                    "relied": [] if self.reduction is None else sorted(self.reduction.relied)}
        ckpt.save(plan.path, {**plan.meta, "engine": ENGINE}, {"visited": visited}, frontier,
                  counters)
        self._last_save = time.monotonic()
        self.saved = plan.path
        return plan.path

    def restore(self, data: Mapping[str, Any]) -> None:
        """Continue a checkpoint `save` wrote (`checker.checkpoint.load`), on this process
        until the frontier is `min_width` wide, whatever number of workers wrote it."""
        c = data["counters"]
        self.states, self.transitions = c["states"], c["transitions"]
        self.initial, self.depth, self.level = c["initial"], c["depth"], c["level"]
        self.peak_frontier = c["peak_frontier"]
        self._elapsed_before, self.roots = c["elapsed"], c["roots"]
        self.traffic = Traffic(**c["traffic"])
        if self.reduction is not None and c.get("publications") is not None:
            self.reduction.relearn(c["publications"])
            self.reduction.stats = ReductionStatistics(**c["reduction"])
            self.reduction.visibility.rises = self.reduction.stats.rises
            self.reduction.relied = set(c.get("relied", ()))
        self.local.shard.visited = visited_from(data["store"]["visited"], self.roots)
        expander = self.local.expander
        for blob in data["frontier"]:
            frontier, graph = unpack(blob)
            expander.frontier += frontier
            if graph is not None and expander.graph is not None:
                expander.graph.extend(graph)
        self.frontier = len(expander.frontier)
        self._restored = True

    def _found(self, failures: list[Failure | None],
               violations: list[tuple[PropertyViolation, int, int] | None]) -> Outcome | None:
        """The outcome of the first handler failure, else the first violation, the workers
        met (a failure's parent, a violating world's key), or None."""
        failure = next((f for f in failures if f is not None), None)
        if failure is not None:
            return self._failed(failure.parent)
        violation = next((v for v in violations if v is not None), None)
        if violation is not None:
            return self._violated(violation[0], self._path(violation[1])[0])
        return None

    def _violated(self, violation: PropertyViolation, path: Counterexample) -> Outcome:
        return Outcome(Status.VIOLATED, violation.property, self.statistics(), violation, path)

    def _failed(self, parent: int) -> Outcome:
        """A handler failed on a step from `parent`: the first failing step from there."""
        path, world = self._path(parent)
        for t in self.system.successors(world):
            if t.failure is not None:
                steps = (*path.steps, t.step)
                return self._violated(self.properties.check_failure(t.failure),
                                      Counterexample(path.initial, steps))
        raise ContractBreachError(_NOT_AGAIN)

    def _path(self, key: int) -> tuple[Counterexample, World]:
        """The steps from an initial world to the world with `key`, along recorded parents."""
        keys = [key]
        lineage = self._ancestry()
        while keys[-1] != ROOT:
            keys += lineage(keys[-1])
        keys.pop()
        keys.reverse()
        initial = self.roots[keys[0]]
        world = self.system.initial_world(initial).world
        steps = []
        for nxt in keys[1:]:
            step = next((t for t in self.system.successors(world)
                         if t.failure is None and t.world.key == nxt), None)
            if step is None:
                raise ContractBreachError(_NOT_AGAIN)
            steps.append(step.step)
            world = step.world
        return Counterexample(initial, tuple(steps)), world

    def _ancestry(self) -> Callable[[int], list[int]]:
        """How `_path` finds a key's ancestors: on the whole visited set, fetched here in
        one call per partition, when a relaxed-order search kept at most `DUMP_STATES`
        (a path over two workers changes partition at about every other step, each
        change a round trip: the crossing fleet's 615-step path took 0.26-0.29 s walked
        so, 0.14-0.16 s fetched whole, the fetch 30 ms of it); else one call per change
        of partition."""
        if self.flow is None or self.states > DUMP_STATES:
            return self._lineage
        whole = visited_from(self.flow.visited(), self.roots)

        def parent(key: int) -> list[int]:
            found = whole.get(key)
            if found is None:
                raise ClusterError(f"the workers' visited sets lack a key of the path: {key}")
            return [found]
        return parent

    def _lineage(self, key: int) -> list[int]:
        if key in self.local.shard.visited:  # found before the hand-over: so are its ancestors
            return self.local.lineage(key)
        return (self.flow or self.backend).lineage(key)

    def _progress(self) -> None:
        now = time.monotonic()
        if self.report is None or now - self._last_report < self.interval:
            return
        self._last_report = now
        elapsed = max(self._elapsed(), 1e-9)  # a resumed search's counts include the runs before
        per = "/".join(f"{n / elapsed:,.0f}" for n in self.traffic.new_per_worker)
        mem = "/".join(f"{b / 2**20:.0f}" for b in self._shard_bytes())
        where = "in this process" if self.backend is self.local and self.flow is None else \
            f"{(self.flow or self.backend).workers} worker(s)"
        self.report(f"[check] {where}  states {self.states:,}  "
                    f"transitions {self.transitions:,}  states/s per worker {per}  "
                    f"depth {self.depth}  frontier {self.frontier:,}  shard memory {mem} MB  "
                    f"{self._elapsed():.0f} s")


_NOT_AGAIN = breach_line(
    FailureKind.NONDETERMINISM, "", "(unknown)", "a path the search recorded does not run "
    "again from its initial world: some handler depends on something outside self.state; "
    f"rerun with --check-determinism to name it; fix: {FIX_HIDDEN}")
