"""The visited-state store: fixed-size digests, compact parent records, compact edges.

States get integer ids in discovery order. Per id the store keeps:

- its key in an index: by default `DigestTable`, 64-bit digests stored by id
  (8 bytes each) plus an int32 open-addressing slot table (linear probing,
  doubled when 75 % full), about 13-19 bytes per state; with
  `--exact-states`, `ExactIndex`, a dict of 128-bit digests (about 100 bytes
  per state);
- its parent id (int32, -1 for initial worlds) for shortest/first-found paths;
  a path of ids is turned back into steps by re-running each world's
  successors and taking the one whose key maps to the next id
  (`checker.paths.steps_along`), so no step is stored;
- one byte "nothing pending" and one byte per `eventually` property
  ("its expression holds here");
- when `eventually` properties are checked, its successors' ids, deduplicated,
  in one shared int32 array (compressed sparse rows: int32 start offset and
  count per expanded state), 8 bytes per state plus 4 per distinct edge.

A 64-bit digest can merge two different states (a false merge: the second
is taken as already visited, so part of the state space may go unexplored).
For n stored states the probability of any such merge is about n²/2^65
(`collision_probability`, TLC's estimate); the content hashes of node states
and events that feed the key add the same term for their own counts. At a
million states that is under 3·10⁻⁸; `--exact-states` makes it ~n²/2^129.
"""

from __future__ import annotations

import sys
from array import array
from typing import Any, final

import numpy as np

_MAX_LOAD = 0.75
_BLOCK_BITS = 13  # keys are kept in blocks of 8,192 (64 KiB): growing never copies them
_PLACE_CHUNK = 2048  # keys entered per vectorised pass when the slot table grows (bounds temporaries)
_BLOCK = 1 << _BLOCK_BITS
_LOW = _BLOCK - 1


@final
class DigestTable:
    """64-bit keys → dense ids 0, 1, 2... (in insertion order), about 13-19 bytes per key.

    Keys are kept by id in fixed-size numpy blocks (8 bytes per key, never
    copied); an int32 slot table (id + 1, 0 = empty slot) is probed linearly
    from `key & mask` and rebuilt at twice the size when 75 % full. So growing
    touches only 4 bytes per slot and the table holds no second copy of the keys.
    """

    def __init__(self, capacity: int = 1 << 12) -> None:
        if capacity & (capacity - 1):
            raise ValueError(f"capacity must be a power of two, got {capacity}")
        self._blocks: list[np.ndarray] = []
        self._bv: list[memoryview] = []  # scalar access from Python is ~30 % faster
        self._n = 0
        self._alloc(capacity)

    def _alloc(self, capacity: int) -> None:
        self._slots = np.zeros(capacity, dtype=np.int32)
        self._sv = self._slots.data  # a memoryview (numpy types memoryview(array) only for 3.12+)
        self._mask = capacity - 1
        self._limit = int(capacity * _MAX_LOAD)

    def __len__(self) -> int:
        return self._n

    @property
    def capacity(self) -> int:
        """Number of slots."""
        return self._mask + 1

    def _slot(self, key: int) -> int:
        """The slot holding `key`, or the empty slot where it would go."""
        sv, bv, mask = self._sv, self._bv, self._mask
        i = key & mask
        while True:
            s = sv[i] - 1
            if s < 0 or bv[s >> _BLOCK_BITS][s & _LOW] == key:
                return i
            i = (i + 1) & mask

    def get(self, key: int) -> int:
        """The id of `key`, or -1."""
        return self._sv[self._slot(key)] - 1

    def setdefault(self, key: int) -> int:
        """The id of `key`; if it has none, give it the next id (`len(self)`) and return that."""
        # `_slot` spelled out: this runs once per transition of a search (a call less each)
        sv, bv, mask = self._sv, self._bv, self._mask
        i = key & mask
        while True:
            found = sv[i] - 1
            if found < 0:
                break
            if bv[found >> _BLOCK_BITS][found & _LOW] == key:
                return found
            i = (i + 1) & mask
        sid = self._n
        if not sid & _LOW:
            self._new_block()
        self._bv[-1][sid & _LOW] = key
        sv[i] = sid + 1
        self._n = sid + 1
        if self._n > self._limit:
            self._alloc(2 * self.capacity)
            for first in range(0, self._n, _PLACE_CHUNK):
                block = self._blocks[first >> _BLOCK_BITS]
                low = first & _LOW
                self._place(block[low:low + min(_PLACE_CHUNK, self._n - first)], first)
        return sid

    def _place(self, keys: np.ndarray, first: int) -> None:
        """Enter `keys` (ids `first`, `first + 1`...) into the slot table, in vectorised
        probing rounds: one winner per free slot, the rest probe on."""
        slots = (keys & np.uint64(self._mask)).astype(np.int64)
        todo = np.arange(len(keys))
        while len(todo):
            cand = slots[todo]
            free = self._slots[cand] == 0
            uniq, pick = np.unique(cand[free], return_index=True)
            winners = todo[free][pick]
            self._slots[uniq] = winners + first + 1
            placed = np.zeros(len(keys), dtype=bool)
            placed[winners] = True
            todo = todo[~placed[todo]]
            slots[todo] = (slots[todo] + 1) & self._mask

    def _new_block(self) -> np.ndarray:
        """Append an empty block of keys (and its memoryview); return it."""
        block = np.zeros(_BLOCK, dtype=np.uint64)
        self._blocks.append(block)
        self._bv.append(block.data)
        return block

    def keys(self) -> np.ndarray:
        """Every key, indexed by id (a copy)."""
        if not self._blocks:
            return np.zeros(0, dtype=np.uint64)
        return np.concatenate(self._blocks)[:self._n]

    def nbytes(self) -> int:
        """Bytes held by the slot table and the key blocks."""
        return int(self._slots.nbytes + len(self._blocks) * _BLOCK * 8)

    def __getstate__(self) -> dict[str, Any]:
        return {"keys": self.keys(), "capacity": self.capacity}

    def __setstate__(self, state: dict[str, Any]) -> None:
        keys = np.asarray(state["keys"], dtype=np.uint64)
        if "ids" in state:  # an older checkpoint: a table of keys (0 = empty) and ids
            used = keys != 0
            keys = keys[used][np.argsort(state["ids"][used], kind="stable")]
        self.__init__(state.get("capacity", len(state["keys"])))
        self.load(keys)

    def load(self, keys: np.ndarray) -> None:
        """Fill an empty table with distinct `keys` (uint64), ids 0, 1, 2... in order."""
        assert self._n == 0, "load fills an empty table"
        capacity = self.capacity
        while len(keys) > capacity * _MAX_LOAD:
            capacity *= 2
        if capacity != self.capacity:
            self._alloc(capacity)
        for start in range(0, len(keys), _BLOCK):
            chunk = keys[start:start + _BLOCK]
            self._new_block()[:len(chunk)] = chunk
            self._n += len(chunk)
        self._place(keys, 0)

    def find_all(self, keys: np.ndarray) -> np.ndarray:
        """The ids of `keys` (uint64), -1 where absent: `get` in vectorised probing rounds."""
        stored = self.keys()
        found = np.full(len(keys), -1, dtype=np.int64)
        slots = (keys & np.uint64(self._mask)).astype(np.int64)
        todo = np.arange(len(keys))
        while len(todo):
            ids = self._slots[slots[todo]].astype(np.int64) - 1
            empty = ids < 0
            hit = ~empty
            hit[hit] = stored[ids[hit]] == keys[todo[hit]]
            found[todo[hit]] = ids[hit]
            todo = todo[~(empty | hit)]
            slots[todo] = (slots[todo] + 1) & self._mask
        return found


@final
class ExactIndex:
    """A dict of 16-byte digests → ids, with DigestTable's interface (`--exact-states`)."""

    def __init__(self) -> None:
        self._ids: dict[bytes, int] = {}

    def __len__(self) -> int:
        return len(self._ids)

    def get(self, key: bytes) -> int:
        """The id stored for `key`, or -1."""
        return self._ids.get(key, -1)

    def setdefault(self, key: bytes) -> int:
        """The id of `key`; if it has none, give it the next id (`len(self)`) and return that."""
        return self._ids.setdefault(key, len(self._ids))

    def nbytes(self) -> int:
        """Bytes of the dict, its keys and its (mostly non-cached) int values."""
        n = len(self._ids)
        return sys.getsizeof(self._ids) + n * (sys.getsizeof(b"\0" * 16) + sys.getsizeof(1 << 20))


@final
class EdgeStore:
    """Successor ids per expanded state in compressed sparse rows."""

    def __init__(self) -> None:
        self.targets = array("i")
        self.start = array("i")  # per state: offset into targets, -1 if not expanded
        self.count = array("i")

    def new_state(self) -> None:
        """Make room for one more state id."""
        self.start.append(-1)
        self.count.append(0)

    @classmethod
    def from_rows(cls, states: int, rows: np.ndarray, counts: np.ndarray,
                  targets: np.ndarray) -> EdgeStore:
        """The store `set` would build for `states` ids, given each expanded id in `rows`,
        its successor count in `counts` and all successors, row after row, in `targets`
        (duplicates within a row dropped, first-seen order kept, as `set` does)."""
        row_of = np.repeat(np.arange(len(rows), dtype=np.int64), counts)
        pairs = row_of * max(states, 1) + targets.astype(np.int64)
        keep = np.sort(np.unique(pairs, return_index=True)[1])
        kept = np.bincount(row_of[keep], minlength=len(rows))
        start = np.full(states, -1, dtype=np.int32)
        count = np.zeros(states, dtype=np.int32)
        start[rows] = np.concatenate(([0], np.cumsum(kept)[:-1])) if len(rows) else []
        count[rows] = kept
        edges = cls()
        edges.targets.frombytes(targets[keep].astype(np.int32).tobytes())
        edges.start.frombytes(start.tobytes())
        edges.count.frombytes(count.tobytes())
        return edges

    def set(self, sid: int, children: list[int]) -> None:
        """Record the successors of `sid` (duplicates dropped, first-seen order kept)."""
        unique = list(dict.fromkeys(children))
        self.start[sid] = len(self.targets)
        self.count[sid] = len(unique)
        self.targets.extend(unique)

    def out(self, sid: int) -> range:
        """Positions in `targets` of the successors of `sid`."""
        begin = self.start[sid]
        return range(0) if begin < 0 else range(begin, begin + self.count[sid])

    def nbytes(self) -> int:
        """Bytes held by the three arrays (allocated size)."""
        return sum(sys.getsizeof(a) for a in (self.targets, self.start, self.count))


@final
class StateStore:
    """Visited states: index (digest → id), parents, flags, roots and optional edges.

    Args:
        exact: key worlds by their 128-bit `World.digest` in a dict instead
            of 64-bit `World.key`s in a `DigestTable`.
        record_edges: keep successor ids (needed by `eventually` properties).
        flags: names of the `eventually` properties, one byte each per state.
    """

    def __init__(self, *, exact: bool = False, record_edges: bool = False,
                 flags: tuple[str, ...] = ()) -> None:
        self.exact = exact
        self.index: DigestTable | ExactIndex = ExactIndex() if exact else DigestTable()
        self.parent = array("i")
        self.terminal = bytearray()
        self.holds: dict[str, bytearray] = {name: bytearray() for name in flags}
        self.roots: dict[int, tuple[int, ...]] = {}
        self.edges = EdgeStore() if record_edges else None
        self.digest_bits = 128 if exact else 64

    @classmethod
    def from_arrays(cls, index: DigestTable, parent: np.ndarray, terminal: bytes,
                    holds: dict[str, bytes], edges: EdgeStore | None) -> StateStore:
        """A store over a filled `index` (ids in its order) with these per-id records, as
        `add`, one key at a time, would have built it."""
        store = cls(record_edges=False, flags=tuple(holds))
        store.index = index
        store.parent.frombytes(parent.astype(np.int32).tobytes())
        store.terminal = bytearray(terminal)
        store.holds = {name: bytearray(bits) for name, bits in holds.items()}
        store.edges = edges
        return store

    def __len__(self) -> int:
        return len(self.parent)

    def add(self, key: Any, parent: int, *, terminal: bool = False) -> tuple[int, bool]:
        """The id of `key`, and whether it is new (then `parent` is recorded; -1 = root)."""
        sid = len(self.parent)
        found = self.index.setdefault(key)
        if found != sid:
            return found, False
        self.parent.append(parent)
        self.terminal.append(terminal)
        if self.edges is not None:
            self.edges.new_state()
        return sid, True

    def find(self, key: Any) -> int:
        """The id of `key`, or -1."""
        return self.index.get(key)

    def path_ids(self, sid: int) -> list[int]:
        """Ids from a root to `sid` along first-discovery parents."""
        ids = [sid]
        while self.parent[ids[-1]] >= 0:
            ids.append(self.parent[ids[-1]])
        return ids[::-1]

    def nbytes(self) -> int:
        """Bytes held by the store (index, per-state records, edges, roots)."""
        total = self.index.nbytes() + sys.getsizeof(self.parent) + sys.getsizeof(self.terminal)
        total += sum(sys.getsizeof(b) for b in self.holds.values())
        total += sys.getsizeof(self.roots) + sum(sys.getsizeof(c) for c in self.roots.values())
        if self.edges is not None:
            total += self.edges.nbytes()
        return total

    def collision_probability(self, hashed: int = 0) -> float:
        """Estimated probability that some stored state was merged with another by a digest.

        Args:
            hashed: how many distinct node states and events got content hashes
                (they feed the 64-bit key; an upper bound is fine).
        """
        n = len(self)
        bits = self.digest_bits
        return min(1.0, (n * (n - 1) + hashed * (hashed - 1)) / 2.0 ** (bits + 1))
