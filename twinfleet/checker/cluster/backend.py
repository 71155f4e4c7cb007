"""Where the coordinator's levels are expanded (`Backend`): this process (`LocalBackend`)
or a cluster of workers and shards (`checker.cluster.engine.RayBackend`), with what the
coordinator counts of the traffic between them and how it saves a search.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol, final

from twinfleet.checker.cluster.flow import FlowBackend
from twinfleet.checker.cluster.level import (
    Acceptance,
    Expander,
    Expansion,
    Graph,
    Item,
    ShardCore,
)
from twinfleet.checker.cluster.visited import VisitedTable
from twinfleet.checker.properties import PropertySet
from twinfleet.checker.reduction import Reduction
from twinfleet.checker.system import System

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
