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

import pickle
import sys
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import cast, final

import numpy as np

from twinfleet.checker.properties import PropertySet, PropertyViolation
from twinfleet.checker.system import System
from twinfleet.checker.world import World

ROOT = -1  # the parent key recorded for an initial world
Item = tuple[World, int, int]  # a frontier world, its key, its depth
_SHIFT = np.uint64(40)  # owners read high bits: a store's slot table reads the low ones


def owners(keys: np.ndarray, shards: int) -> np.ndarray:
    """The shard index owning each key of `keys` (uint64)."""
    return ((keys >> _SHIFT) % np.uint64(shards)).astype(np.int64)


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


@final
@dataclass(slots=True)
class Acceptance:
    """What a worker kept after the shards answered its claims."""

    new: int = 0
    depth: int = 0
    frontier: int = 0
    violation: tuple[PropertyViolation, int, int] | None = None  # violation, key, depth
    min_due: int | None = None


@final
class Expander:
    """One worker's frontier and its level-by-level expansion (module docstring)."""

    def __init__(self, system: System, properties: PropertySet, shards: int) -> None:
        self.system = system
        self.properties = properties
        self.shards = shards
        self.frontier: list[Item] = []
        self._pending: list[list[tuple[World, int]]] = []

    def expand(self, max_depth: int | None) -> tuple[Expansion, list[bytes]]:
        """Expand every frontier world; return the counts and one packed claim blob per
        shard (keys then parent keys, uint64)."""
        out = Expansion()
        seen: set[int] = set()
        worlds: list[list[tuple[World, int]]] = [[] for _ in range(self.shards)]
        keys: list[list[int]] = [[] for _ in range(self.shards)]
        parents: list[list[int]] = [[] for _ in range(self.shards)]
        successors, shards = self.system.successors, self.shards
        for world, key, depth in self.frontier:
            if max_depth is not None and depth >= max_depth:
                out.pruned = True
                continue
            for t in successors(world):
                out.transitions += 1
                if t.failure is not None:
                    if out.failure is None:
                        out.failure = Failure(key, depth + 1)
                    continue
                child = cast(int, t.world.key)  # --exact-states never runs here
                if child in seen:
                    continue
                seen.add(child)
                s = (child >> 40) % shards
                worlds[s].append((t.world, depth + 1))
                keys[s].append(child)
                parents[s].append(key)
        self.frontier = []
        self._pending = worlds
        out.claims = len(seen)
        return out, [pack_pairs(k, p) for k, p in zip(keys, parents, strict=True)]

    def accept(self, masks: list[bytes]) -> Acceptance:
        """Keep the claimed worlds the shards answered new; check the properties on them."""
        out = Acceptance()
        check = self.properties.check_world
        frontier = self.frontier
        for pending, mask in zip(self._pending, masks, strict=True):
            flags = np.frombuffer(mask, dtype=np.bool_)
            for (world, depth), new in zip(pending, flags.tolist(), strict=True):
                if not new:
                    continue
                out.new += 1
                out.depth = max(out.depth, depth)
                key = cast(int, world.key)
                frontier.append((world, key, depth))
                if out.violation is None:
                    violation = check(self.system, world)
                    if violation is not None:
                        out.violation = (violation, key, depth)
        self._pending = []
        out.frontier = len(frontier)
        dues = [w.events[0].due for w, _, _ in frontier if w.events]
        out.min_due = min(dues) if dues else None
        return out

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
        """The whole frontier as one blob (`take` reads it), kept here (a checkpoint)."""
        return pickle.dumps(self.frontier, protocol=pickle.HIGHEST_PROTOCOL)


def pack_pairs(keys: list[int], parents: list[int]) -> bytes:
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
    """One partition of the visited set: key -> parent key (ROOT for initial worlds)."""

    parents: dict[int, int] = field(default_factory=dict)

    def claim(self, blobs: list[bytes]) -> list[bytes]:
        """Answer each worker's claims (in worker order, so a key claimed by two workers
        goes to the first): one new/seen mask per blob."""
        parents = self.parents
        out = []
        for blob in blobs:
            keys, pars = unpack_claims(blob)
            mask = np.zeros(len(keys), dtype=np.bool_)
            for i, (k, p) in enumerate(zip(keys.tolist(), pars.tolist(), strict=True)):
                if k not in parents:
                    parents[k] = p
                    mask[i] = True
            out.append(mask.tobytes())
        return out

    def add(self, keys: list[int], parents: list[int]) -> None:
        """Enter known states (a search handed over from one process)."""
        self.parents.update(zip(keys, parents, strict=True))

    def parent(self, key: int) -> int:
        """The parent key of a stored key (ROOT for an initial world)."""
        return self.parents[key]

    def dump(self) -> bytes:
        """The partition as one `pack_pairs` blob; an initial world's parent is written as
        0 (a checkpoint records which keys are initial, `visited_from` reads it back)."""
        return pack_pairs(list(self.parents), [max(p, 0) for p in self.parents.values()])

    def nbytes(self) -> int:
        """Bytes the partition holds (the dict and its int objects, roughly)."""
        return sys.getsizeof(self.parents) + 64 * len(self.parents)


def visited_from(blobs: list[bytes], roots: Iterable[int]) -> dict[int, int]:
    """The visited set (key -> parent key) of `ShardCore.dump` blobs; `roots`: the keys of
    initial worlds."""
    parents: dict[int, int] = {}
    for blob in blobs:
        keys, pars = unpack_claims(blob)
        parents.update(zip(keys.tolist(), pars.tolist(), strict=True))
    for key in roots:
        parents[key] = ROOT
    return parents
