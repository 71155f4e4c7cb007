"""The sans-IO cores of the distributed search: a worker's expansion and a shard's claims.

A `Expander` holds the frontier worlds its worker discovered and expands one
BFS level of them at a time. Every successor becomes a *claim* (its 64-bit
key and its parent's key), deduplicated within the level and grouped by the
shard that owns the key (`owner`); the world itself stays here. A `ShardCore`
owns a slice of the visited set (key -> parent key) and answers a batch of
claims with a new/seen mask; the expander keeps the worlds that are new,
checks the safety properties on them, and they become its next level. So a
world is expanded by the worker that found it (its outcome cache stays
useful) and only 16 bytes per edge cross between processes.

Neither class does any I/O: `checker.cluster.engine` wraps them in Ray
actors, `checker.cluster.coordinator` runs them in this process for a search
that stays narrow.
"""

from __future__ import annotations

import dataclasses
import pickle
from array import array
from collections.abc import Iterable, Iterator, MutableSequence, Sequence
from dataclasses import dataclass, field
from typing import Any, cast, final

import numpy as np

from twinfleet.checker.cluster.visited import ROOT, VisitedTable
from twinfleet.checker.properties import PropertySet, PropertyViolation
from twinfleet.checker.publications import Edge
from twinfleet.checker.reduction import Reduction, ReductionStatistics
from twinfleet.checker.store import DigestTable, EdgeStore, StateStore
from twinfleet.checker.system import System
from twinfleet.checker.transition import Transition
from twinfleet.checker.world import World, earliest_time

Item = tuple[World, int, int]  # a frontier world, its key, its depth
_SHIFT = np.uint64(40)  # owners read high bits: a store's slot table reads the low ones


def owners(keys: np.ndarray, shards: int) -> np.ndarray:
    """The shard index owning each key of `keys` (uint64)."""
    return ((keys >> _SHIFT) % np.uint64(shards)).astype(np.int64)


def split(visited: VisitedTable, shards: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """A visited set's keys and parent keys, one pair of arrays per owning shard."""
    keys, parents = visited.arrays()
    by = owners(keys, shards)
    return [(keys[by == i], parents[by == i]) for i in range(shards)]


def owner(key: int, shards: int) -> int:
    """The shard index owning `key`."""
    return (key >> 40) % shards


@final
@dataclass(frozen=True, slots=True)
class Failure:
    """A transition whose handler failed: found from the world with key `parent`."""

    parent: int
    depth: int  # the failing step's depth (the parent's depth + 1)


@final
@dataclass(slots=True)
class Expansion:
    """What expanding one level produced: transitions taken, a failure, pruned worlds."""

    transitions: int = 0
    failure: Failure | None = None
    pruned: bool = False
    claims: int = 0


_COUNTERS = ("reduced", "full", "cycle_proviso", "commuted", "pairs", "refuted")


@final
@dataclass(slots=True)
class Graph:
    """What a worker saw of the graph, for `eventually` properties (a lasso search over
    the whole graph, gathered to the coordinator): every world it kept (key, whether
    nothing is pending there, whether each property holds there) and the successor keys
    of every world it expanded."""

    keys: array[int] = field(default_factory=lambda: array("Q"))
    terminal: bytearray = field(default_factory=bytearray)
    holds: list[bytearray] = field(default_factory=list)  # one per eventually property
    expanded: array[int] = field(default_factory=lambda: array("Q"))
    counts: array[int] = field(default_factory=lambda: array("I"))
    children: array[int] = field(default_factory=lambda: array("Q"))

    def keep(self, system: System, properties: PropertySet, world: World, key: int) -> None:
        """Record a world the search keeps."""
        self.keys.append(key)
        self.terminal.append(not world.events)
        if not self.holds:
            self.holds = [bytearray() for _ in properties.eventually]
        for bits, prop in zip(self.holds, properties.eventually, strict=True):
            assert prop.expr is not None
            bits.append(prop.expr.holds(system, world.states, world.now))

    def extend(self, other: Graph) -> None:
        """Add another worker's records."""
        self.keys += other.keys
        self.terminal += other.terminal
        if not self.holds:
            self.holds = [bytearray() for _ in other.holds]
        for mine, theirs in zip(self.holds, other.holds, strict=False):
            mine += theirs
        self.expanded += other.expanded
        self.counts += other.counts
        self.children += other.children

    def store(self, visited: list[bytes], roots: Iterable[int], names: tuple[str, ...]
              ) -> StateStore:
        """The graph as a one-process search records it (ids in this graph's order,
        first-discovery parents from the shards' `visited` dumps, `roots` the initial
        keys, `names` the eventually properties), built with array operations: millions
        of worlds take seconds, not a minute."""
        keys = np.frombuffer(self.keys, dtype=np.uint64)
        pairs = [unpack_claims(blob) for blob in visited]
        known = np.concatenate([k for k, _ in pairs]) if pairs else np.zeros(0, np.uint64)
        parent_keys = np.concatenate([p for _, p in pairs]) if pairs else known
        order = np.argsort(known, kind="stable")
        at = order[np.searchsorted(known, keys, sorter=order)]
        index = DigestTable()
        index.load(keys)
        parent = index.find_all(parent_keys[at])
        parent[np.isin(keys, np.fromiter(roots, dtype=np.uint64))] = -1
        edges = EdgeStore.from_rows(
            len(keys), index.find_all(np.frombuffer(self.expanded, dtype=np.uint64)),
            np.frombuffer(self.counts, dtype=np.uint32).astype(np.int64),
            index.find_all(np.frombuffer(self.children, dtype=np.uint64)))
        holds = {name: bytes(bits) for name, bits in zip(names, self.holds, strict=True)}
        return StateStore.from_arrays(index, parent, bytes(self.terminal), holds, edges)


@final
@dataclass(frozen=True, slots=True)
class Learned:
    """What a worker's reduced search learned and counted at one level."""

    edges: frozenset[Edge]
    unknown: str | None
    fell: str | None  # a rising goal's atom seen falling (`Visibility.pending_fall`)
    counted: dict[str, int]
    relied: frozenset[str]

    def grew(self) -> bool:
        """Whether what the search relies on changed (it then starts again)."""
        return bool(self.edges) or self.unknown is not None or self.fell is not None


@final
@dataclass(slots=True)
class Acceptance:
    """What a worker kept after the shards answered its claims."""

    new: int = 0
    depth: int = 0
    frontier: int = 0
    violation: tuple[PropertyViolation, int, int] | None = None  # violation, key, depth
    min_due: int | None = None
    learned: Learned | None = None  # a reduced search's sends learned, counters
    handler_runs: int = 0  # handlers this worker has run so far (its outcome cache missed)


@final
class Expander:
    """One worker's frontier and its level-by-level expansion (module docstring).

    With a `reduction` a level has two halves: `propose` finds each world's persistent
    set and asks the shards whether the successors that stay at the world's instant are
    stored (the cycle proviso; the shards hold exactly the worlds at most as deep as the
    level then), and `expand` takes the sets, or every transition where one is.
    """

    def __init__(self, system: System, properties: PropertySet, shards: int,
                 reduction: Reduction | None = None) -> None:
        self.system = system
        self.properties = properties
        self.shards = shards
        self.reduction = reduction
        self.frontier: list[Item] = []
        self.pending: list[list[tuple[World, int]]] = []  # claimed worlds, per shard
        self._proposals: list[tuple[Item, list[Transition], list[int] | None]] = []
        self._probes: list[list[int]] = []
        self._counted = ReductionStatistics()
        self._rises = 0
        self.graph = Graph() if properties.eventually else None

    def propose(self, max_depth: int | None) -> list[bytes]:
        """Reduced search, first half of a level: the persistent sets; one blob of keys
        (uint64) per shard whose storing decides the cycle proviso."""
        reduction = self.reduction
        assert reduction is not None
        self._proposals = []
        probes: list[list[int]] = [[] for _ in range(self.shards)]
        for item in self.frontier:
            if max_depth is not None and item[2] >= max_depth:
                continue
            out, found = reduction.candidates(item[0])
            keys = cast("list[int] | None", found)  # 64-bit digests: --exact-states stays home
            self._proposals.append((item, out, keys))
            for key in keys or ():
                probes[owner(key, self.shards)].append(key)
        self._probes = probes
        return [np.array(k, dtype=np.uint64).tobytes() for k in probes]

    def _level(self, max_depth: int | None, stored: list[bytes] | None, out: Expansion,
               items: Iterable[Item] | None) -> Iterator[tuple[int, int, Iterable[Transition]]]:
        """(key, depth, transitions taken) of every frontier world expanded at this level
        (or of `items`, unreduced)."""
        if self.reduction is None:
            for world, key, depth in self.frontier if items is None else items:
                if max_depth is not None and depth >= max_depth:
                    out.pruned = True
                    continue
                yield key, depth, self.system.successors(world)
            return
        out.pruned = len(self._proposals) < len(self.frontier)
        found: set[int] = set()
        for keys, mask in zip(self._probes, stored or [], strict=True):
            found.update(k for k, hit in zip(keys, np.frombuffer(mask, dtype=np.bool_).tolist(),
                                             strict=True) if hit)
        reduction = self.reduction
        for (world, key, depth), candidates, probes in self._proposals:
            if probes is None:
                taken = candidates
            elif any(k in found for k in probes):
                taken = reduction.full(world)
            else:
                taken = reduction.reduced(world, candidates)
            yield key, depth, taken
        self._proposals, self._probes = [], []

    def expand(self, max_depth: int | None, stored: list[bytes] | None = None,
               items: Iterable[Item] | None = None) -> tuple[Expansion, list[bytes]]:
        """Expand every frontier world (reduced: by the sets `propose` found, `stored`
        the shards' answers), or, unreduced, the worlds `items` yields instead; return the
        counts and one packed claim blob per shard (keys then parent keys, uint64)."""
        out = Expansion()
        seen: set[int] = set()
        worlds: list[list[tuple[World, int]]] = [[] for _ in range(self.shards)]
        keys: list[list[int]] = [[] for _ in range(self.shards)]
        parents: list[list[int]] = [[] for _ in range(self.shards)]
        shards, graph, count = self.shards, self.graph, 0
        # The inner loop of a worker: locals only, no call a transition can do without.
        for key, depth, transitions in self._level(max_depth, stored, out, items):
            if graph is not None:
                graph.expanded.append(key)
                graph.counts.append(0)
            below = depth + 1
            for t in transitions:
                count += 1
                if t.failure is not None:
                    if out.failure is None:
                        out.failure = Failure(key, below)
                    continue
                world = t.world
                child: int = world.key  # type: ignore[assignment] # no --exact-states here
                if graph is not None:
                    graph.counts[-1] += 1
                    graph.children.append(child)
                if child in seen:
                    continue
                seen.add(child)
                s = (child >> 40) % shards
                worlds[s].append((world, below))
                keys[s].append(child)
                parents[s].append(key)
        out.transitions += count
        self.frontier = []
        self.pending = worlds
        out.claims = len(seen)
        return out, [pack_pairs(k, p) for k, p in zip(keys, parents, strict=True)]

    def learned(self) -> Learned | None:
        """Reduced search, at the end of a level: the sends learned and the reduction's
        counters since the last call, or None when nothing was learned nor counted."""
        reduction = self.reduction
        if reduction is None:
            return None
        now = dataclasses.replace(reduction.stats)
        counted = {f: getattr(now, f) - getattr(self._counted, f) for f in _COUNTERS}
        counted["rises"] = reduction.visibility.rises - self._rises
        self._counted, self._rises = now, reduction.visibility.rises
        edges, unknown = reduction.publications.learned()
        return Learned(edges, unknown, reduction.visibility.pending_fall, counted,
                       frozenset(reduction.relied))

    def relearn(self, state: tuple[Any, ...]) -> None:
        """Start again from scratch with `state` (`Reduction.learned_state` of the
        coordinator's, everything learned merged): an empty frontier, counters at 0."""
        reduction = self.reduction
        assert reduction is not None
        reduction.relearn(state)
        self._counted = ReductionStatistics()
        self._rises = 0
        self.frontier, self.pending, self._proposals, self._probes = [], [], [], []
        self.graph = Graph() if self.properties.eventually else None

    def accept(self, masks: list[bytes]) -> Acceptance:
        """Keep the claimed worlds the shards answered new; check the properties on them."""
        out = Acceptance()
        frontier = self.frontier
        for pending, mask in zip(self.pending, masks, strict=True):
            self.keep(pending, mask, out, frontier)
        self.pending = []
        out.frontier = len(frontier)
        out.learned = self.learned()
        out.handler_runs = self.system.runner.handler_runs
        out.min_due = earliest_time(w for w, _, _ in frontier)
        return out

    def keep(self, pending: Sequence[tuple[World, int]], mask: bytes, out: Acceptance,
             into: MutableSequence[Item]) -> None:
        """Append to `into` the worlds of `pending` (claimed, with their depths) that
        `mask` (a shard's answer) says are new, counting them and checking the safety
        properties on them into `out` (the first violation is kept)."""
        check = self.properties.check_world
        for (world, depth), new in zip(pending, np.frombuffer(mask, dtype=np.bool_).tolist(),
                                       strict=True):
            if not new:
                continue
            out.new += 1
            out.depth = max(out.depth, depth)
            key = cast(int, world.key)
            into.append((world, key, depth))
            if self.graph is not None:
                self.graph.keep(self.system, self.properties, world, key)
            if out.violation is None:
                violation = check(self.system, world)
                if violation is not None:
                    out.violation = (violation, key, depth)

    def forget_before(self, time_ms: int) -> None:
        """Let the system drop cached outcomes no world left to expand can use."""
        self.system.forget_before(time_ms)

    def give(self, count: int) -> bytes:
        """Hand `count` frontier worlds to an idle worker, as one packed blob."""
        count = min(count, len(self.frontier))
        given, self.frontier = self.frontier[len(self.frontier) - count:], \
            self.frontier[:len(self.frontier) - count]
        return pickle.dumps(given, protocol=pickle.HIGHEST_PROTOCOL)

    def take(self, blob: bytes) -> int:
        """Add the worlds of a blob from `give`; return the frontier's size."""
        self.frontier.extend(pickle.loads(blob))  # noqa: S301 - from our own workers
        return len(self.frontier)

    def packed(self) -> bytes:
        """The frontier and the graph records as one blob (`unpack`), kept here (a
        checkpoint)."""
        return pickle.dumps((self.frontier, self.graph), protocol=pickle.HIGHEST_PROTOCOL)


def unpack(blob: bytes) -> tuple[list[Item], Graph | None]:
    """The frontier and graph records of an `Expander.packed` blob."""
    frontier, graph = pickle.loads(blob)  # noqa: S301 - our own checkpoint
    return frontier, graph


def pack_pairs(keys: Sequence[int] | np.ndarray, parents: Sequence[int] | np.ndarray) -> bytes:
    """One blob of keys then parent keys (uint64): a claim batch, or a visited set."""
    return np.array(keys, dtype=np.uint64).tobytes() + np.array(parents, dtype=np.uint64).tobytes()


def unpack_claims(blob: bytes) -> tuple[np.ndarray, np.ndarray]:
    """The keys and parent keys of a blob from `pack_pairs`."""
    both = np.frombuffer(blob, dtype=np.uint64)
    half = len(both) // 2
    return both[:half], both[half:]


@final
@dataclass
class ShardCore:
    """One partition of the visited set: key -> parent key (`VisitedTable`)."""

    visited: VisitedTable = field(default_factory=VisitedTable)

    def claim(self, blobs: list[bytes]) -> list[bytes]:
        """Answer each worker's claims (in worker order, so a key claimed by two workers
        goes to the first): one new/seen mask per blob."""
        return [self.visited.add(*unpack_claims(blob)).tobytes() for blob in blobs]

    def stored(self, blobs: list[bytes]) -> list[bytes]:
        """Whether each key of each blob (uint64 keys, from `Expander.propose`) is stored:
        one mask per blob."""
        return [self.visited.contains(np.frombuffer(b, dtype=np.uint64)).tobytes()
                for b in blobs]

    def clear(self) -> None:
        """Forget every key (a reduced search starts again)."""
        self.visited = VisitedTable()

    def drain(self) -> bytes:
        """`dump`, then forget every key (the search goes back to the coordinator)."""
        blob = self.dump()
        self.clear()
        return blob

    def add(self, keys: np.ndarray, parents: np.ndarray) -> None:
        """Enter known states (a search handed over from one process)."""
        self.visited.add(keys, parents)

    def parent(self, key: int) -> int:
        """The parent key of a stored key (ROOT for an initial world)."""
        parent = self.visited.get(key)
        if parent is None:
            raise KeyError(key)
        return parent

    def lineage(self, key: int, index: int, shards: int) -> list[int]:
        """The parent of a stored key and its ancestors while this partition (number
        `index` of `shards`) holds them: ends with ROOT or with the first key another
        partition holds. A counterexample's path is walked with one call per change of
        partition instead of one per step (a call to a busy worker takes milliseconds)."""
        found = [self.parent(key)]
        while found[-1] != ROOT and owner(found[-1], shards) == index:
            found.append(self.parent(found[-1]))
        return found

    def dump(self) -> bytes:
        """The partition as one `pack_pairs` blob; an initial world's parent is written as
        0 (a checkpoint records which keys are initial, `visited_from` reads it back)."""
        return pack_pairs(*self.visited.arrays())

    def nbytes(self) -> int:
        """Bytes the partition holds."""
        return self.visited.nbytes()


def visited_from(blobs: list[bytes], roots: Iterable[int]) -> VisitedTable:
    """The visited set of `ShardCore.dump` blobs; `roots`: the keys of initial worlds."""
    visited = VisitedTable()
    for blob in blobs:
        visited.add(*unpack_claims(blob))
    for key in roots:
        visited.put(key, ROOT)
    return visited
