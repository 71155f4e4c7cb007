"""Where the coordinator's levels are expanded (`Backend`): this process (`LocalBackend`)
or a cluster of workers and shards (`checker.cluster.engine.RayBackend`), with what the
coordinator counts of the traffic between them and how it saves a search.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol, cast, final

from twinfleet.checker.cluster.flow import FlowBackend
from twinfleet.checker.cluster.level import (
    Acceptance,
    Expander,
    Expansion,
    Graph,
    Item,
    ShardCore,
    visited_from,
)
from twinfleet.checker.cluster.visited import VisitedTable
from twinfleet.checker.properties import PropertySet
from twinfleet.checker.reduction import Reduction
from twinfleet.checker.system import System

START_POLL_S = 0.01  # how often a search that waits for its workers asks if they are up
STEAL_MIN = 64  # frontier worlds two workers must differ by before some are moved


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


TICK_WORLDS = 512  # worlds of a local level between two ticks (~10-30 ms of expansion)


def _ticking(frontier: list[Item], tick: Callable[[], None]) -> Iterator[Item]:
    """The frontier's worlds, calling `tick` before every TICK_WORLDS-th."""
    for i, item in enumerate(frontier):
        if i % TICK_WORLDS == 0:
            tick()
        yield item


@final
class LocalBackend:
    """One expander and one shard in this process."""

    workers = 1

    def __init__(self, system: System, properties: PropertySet,
                 reduction: Reduction | None = None,
                 tick: Callable[[], None] | None = None) -> None:
        self.expander = Expander(system, properties, 1, reduction)
        self.shard = ShardCore()
        self._fresh = True  # used as a cluster: the coordinator's relation not learned yet
        # Called every TICK_WORLDS worlds of an unreduced level (Ctrl-C, max-time): a level
        # of a wide search takes seconds here. A `Stop` it raises leaves the frontier as the
        # level found it, so only a search that saves no checkpoint is given one.
        self.tick = tick

    def ready(self) -> bool:
        """Always (`Backend.ready`)."""
        return True

    def level(self, max_depth: int | None) -> tuple[list[Expansion], list[Acceptance]]:
        """One level here (`Backend.level`)."""
        stored = None
        if self.expander.reduction is not None:
            stored = self.shard.stored(self.expander.propose(max_depth))
        items = None
        if self.tick is not None and stored is None:
            items = _ticking(self.expander.frontier, self.tick)
        expansion, blobs = self.expander.expand(max_depth, stored, items)
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


def balance(backend: Backend, sizes: list[int], traffic: Traffic) -> None:
    """Move worlds from the busiest worker to the idlest (work sharing), when their
    frontiers differ by more than `STEAL_MIN`."""
    if len(sizes) < 2:
        return
    busy = max(range(len(sizes)), key=sizes.__getitem__)
    idle = min(range(len(sizes)), key=sizes.__getitem__)
    gap = sizes[busy] - sizes[idle]
    if gap > STEAL_MIN:
        backend.move(busy, idle, gap // 2)
        traffic.stolen += gap // 2
        traffic.moves += 1


@final
class Placement:
    """Where the coordinator's levels run, and when the search moves.

    The search starts here (`local`). Once a level's frontier is `min_width` wide the
    cluster's backend is started (once: a restart reuses it) while the search goes on
    here, and when its workers are up the frontier and the visited set are handed to it
    (`cluster`), or to the workers of a relaxed order (`flow`), which then keep the
    rest of the search. A frontier narrower than `back_width` for `patience` levels in
    a row comes back here, the patience doubling after each return (a move costs time
    in proportion to the visited set).

    Args:
        system, properties, reduction: what a new local backend searches.
        factory: starts the cluster's backend; None: everything in this process.
        flow_factory: starts the workers of a relaxed order instead, or None.
        min_width, back_width, patience, start_states: as `Coordinator` takes them.
        tick: called while waiting for the workers (Ctrl-C, max-time), and, with
            `tick_within_levels`, inside the levels searched here (`LocalBackend`).
        report: called with a line when the workers are up, or None.
    """

    def __init__(self, system: System, properties: PropertySet, reduction: Reduction | None,
                 factory: Factory | None, flow_factory: FlowFactory | None, *,
                 min_width: int, back_width: int, patience: int, tick: Callable[[], None],
                 start_states: int = 0, tick_within_levels: bool = False,
                 report: Callable[[str], None] | None) -> None:
        self.system, self.properties, self.reduction = system, properties, reduction
        self.factory, self.flow_factory = factory, flow_factory
        self.min_width, self.back_width = min_width, back_width
        self.patience, self._narrow = patience, 0
        self.tick, self.report = tick, report
        self.start_states = start_states
        self.started_at: int | None = None  # the level where the cluster started
        self._level_tick = tick if tick_within_levels else None
        self.local = self._new_local()
        self.backend: Backend = self.local
        self.cluster: Backend | None = None
        self.flow: FlowBackend | None = None  # the relaxed order's workers, once searching
        self._starting: Backend | FlowBackend | None = None  # the cluster's, once started
        self.distributed_at: int | None = None  # the level where the cluster took over

    @property
    def current(self) -> Backend | FlowBackend:
        """Where the search is now."""
        return self.flow or self.backend

    def before_level(self, width: int, level: int, roots: dict[int, tuple[int, ...]],
                     traffic: Traffic, states: int = 0) -> bool:
        """Move the search to where a level `width` wide at depth `level` runs, `states`
        found so far; True if the relaxed order's workers are up to take the rest of it
        (`to_flow`)."""
        if self.backend is self.local and self.factory is not None and \
                width >= self.min_width and self._started(width, level, states):
            if self.flow_factory is not None:
                return True
            self._to_cluster(level)
        elif self.backend is not self.local:
            self._narrow = self._narrow + 1 if width < self.back_width else 0
            if self._narrow >= self.patience << traffic.returns:
                self._to_local(roots, traffic)
        return False

    def _started(self, width: int, level: int, states: int) -> bool:
        """Start the cluster's backend, once, and say whether its workers are up. They
        start while the search goes on here (a worker process takes a second or two to
        import the node code and build its system: time this process spends searching),
        except with `min_width` 1, which asks for the whole search on the workers: then
        this waits for them. A search of fewer than `start_states` states starts nothing."""
        if self._starting is None:
            if states < self.start_states:
                return False
            if self.flow_factory is not None:
                self._starting = self.flow_factory(width)
            else:
                assert self.factory is not None
                self._starting = self.factory(width)
            self.started_at = level
        while not self._starting.ready():
            if self.min_width > 1:
                return False
            self.tick()
            time.sleep(START_POLL_S)
        if self.report is not None and self.distributed_at is None:
            self.report(f"[check] {self._starting.workers} worker(s) up: the search moves "
                        f"to them at depth {level}, frontier {width:,} wide")
        return True

    def _to_cluster(self, level: int) -> None:
        """Hand the frontier and the visited set to the cluster's backend."""
        self.cluster = cast(Backend, self._starting)
        self.cluster.load(self.local.expander.frontier, self.local.shard.visited,
                          self.relation())
        self.local.expander.frontier = []
        self.backend = self.cluster
        if self.distributed_at is None:
            self.distributed_at = level

    def _to_local(self, roots: dict[int, tuple[int, ...]], traffic: Traffic) -> None:
        """Take the frontier and the visited set back from the cluster."""
        frontier, visited = self.backend.take_back()
        self.local.expander.frontier = frontier
        self.local.shard.visited = visited_from(visited, roots)
        self.backend = self.local
        traffic.returns += 1
        self._narrow = 0

    def to_flow(self, level: int) -> FlowBackend:
        """Hand the frontier and the visited set to the relaxed order's workers, for good."""
        flow = self.flow = cast(FlowBackend, self._starting)
        self.distributed_at = level
        flow.load(self.local.expander.frontier, self.local.shard.visited)
        self.local.expander.frontier = []
        return flow

    def relation(self) -> tuple[Any, ...] | None:
        """The send relation a reduced search learned so far (None: no reduction)."""
        return None if self.reduction is None else self.reduction.learned_state()

    def restart(self) -> None:
        """Search from scratch here with what the reduction learned; the cluster, if it
        took part, forgets its search."""
        if self.cluster is not None:
            self.cluster.reset(self.relation())
        self.local = self._new_local()
        self.backend = self.local

    def _new_local(self) -> LocalBackend:
        return LocalBackend(self.system, self.properties, self.reduction, self._level_tick)

    def graph(self) -> tuple[list[Graph], list[bytes]]:
        """What every worker saw of the graph and every shard's visited keys, at the end
        (`walk.gathered`)."""
        remote = self.flow if self.flow is not None else self.cluster
        parts = [*self.local.graphs(), *(() if remote is None else remote.graphs())]
        if self.flow is not None:
            visited = self.flow.visited()
        elif self.backend is self.local:
            visited = [self.local.shard.dump()]
        else:
            visited = self.backend.snapshot()[1]
        return parts, visited

    def lineage(self, key: int) -> list[int]:
        """`Backend.lineage` from where `key` was found."""
        if key in self.local.shard.visited:  # found before the hand-over: so are its ancestors
            return self.local.lineage(key)
        return self.current.lineage(key)
