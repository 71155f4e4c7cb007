"""A shard's part of the visited set: 64-bit keys and their parents' keys, in arrays.

An open-addressing table of two uint64 arrays, a world's key and its parent's key
in the same slot (linear probing from the key's low bits, doubled when 3/4 full):
16 bytes a slot, 21-43 bytes a world, where a dict of Python ints costs about 115.
Every operation takes a batch of keys and runs in vectorised probing rounds, so a
shard answers a level's claims with a few numpy calls, not a loop of dict lookups
in Python; a batch of at most `FEW` keys is probed key by key instead, since those
numpy calls cost 0.2 ms together however few keys they take (a relaxed-order
worker answers a claim batch of a few dozen keys at every turn of its loop).
The key 0 marks an empty slot; a world whose key is 0 is kept beside the arrays.
A parent key of 0 stands for "an initial world" (`ROOT`), as in the blobs of
`dump`, which the coordinator reads with the keys of the initial worlds beside.
"""

from __future__ import annotations

import numpy as np

ROOT = -1  # the parent key `get` answers for an initial world
_EMPTY = np.uint64(0)
_MAX_LOAD = 0.75
_CHUNK = 1 << 16  # keys placed per vectorised pass when the table grows (bounds temporaries)
FEW = 512  # batches up to this size are probed key by key (0.5-1 us a key; numpy: 0.2 ms
# a call and 0.5 us a key, measured on this project's 2-core machine)


class VisitedTable:
    """Keys -> parent keys (module docstring)."""

    __slots__ = ("_keys", "_mask", "_n", "_parents", "_zero")

    def __init__(self, capacity: int = 1 << 10) -> None:
        if capacity & (capacity - 1):
            raise ValueError(f"capacity must be a power of two, got {capacity}")
        self._keys = np.zeros(capacity, dtype=np.uint64)
        self._parents = np.zeros(capacity, dtype=np.uint64)
        self._mask = np.uint64(capacity - 1)
        self._n = 0
        self._zero: int | None = None  # the parent of a world whose key is 0, if stored

    def __len__(self) -> int:
        return self._n + (self._zero is not None)

    def _slots(self, keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For each key (none 0): its slot, or the empty slot where it would go; and
        whether it is there."""
        table, mask = self._keys, self._mask
        slots = keys & mask
        found = np.zeros(len(keys), dtype=np.bool_)
        todo = np.arange(len(keys))
        while len(todo):
            held = table[slots[todo]]
            hit = held == keys[todo]
            found[todo[hit]] = True
            todo = todo[~(hit | (held == _EMPTY))]
            slots[todo] = (slots[todo] + np.uint64(1)) & mask
        return slots, found

    def _slot(self, key: int) -> tuple[int, bool]:
        """`_slots` of one key (none 0)."""
        return _probe(self._keys.data, int(self._mask), key)

    def contains(self, keys: np.ndarray) -> np.ndarray:
        """Whether each of `keys` (uint64) is stored."""
        keys = np.asarray(keys, dtype=np.uint64)
        if len(keys) <= FEW:
            table, mask, zero = self._keys.data, int(self._mask), self._zero is not None
            return np.array([_probe(table, mask, k)[1] if k else zero for k in keys.tolist()],
                            dtype=np.bool_)
        zero = keys == _EMPTY
        found = np.zeros(len(keys), dtype=np.bool_)
        found[~zero] = self._slots(keys[~zero])[1]
        found[zero] = self._zero is not None
        return found

    def add(self, keys: np.ndarray, parents: np.ndarray) -> np.ndarray:
        """Store every key not stored yet with its parent (of keys repeated in the batch,
        the first): a mask of the keys stored by this call."""
        keys = np.asarray(keys, dtype=np.uint64)
        parents = np.asarray(parents, dtype=np.uint64)
        if len(keys) <= FEW:
            return self._add_few(keys.tolist(), parents.tolist())
        new = np.flatnonzero(~self.contains(keys))
        if len(new):
            new = np.sort(new[np.unique(keys[new], return_index=True)[1]])
        stored = np.zeros(len(keys), dtype=np.bool_)
        stored[new] = True
        zero = new[keys[new] == _EMPTY]
        if len(zero):
            self._zero = int(parents[zero[0]])
            new = new[keys[new] != _EMPTY]
        self._grow_for(self._n + len(new))
        self._place(keys[new], parents[new])
        return stored

    def _add_few(self, keys: list[int], parents: list[int]) -> np.ndarray:
        """`add` key by key (a batch of at most `FEW`); the table grows first, so that the
        slots probed stay where they are."""
        self._grow_for(self._n + len(keys))
        table, links, mask = self._keys.data, self._parents.data, int(self._mask)
        stored = []
        for key, parent in zip(keys, parents, strict=True):
            if not key:
                new = self._zero is None
                if new:
                    self._zero = parent
            else:
                slot, found = _probe(table, mask, key)
                new = not found
                if new:
                    table[slot], links[slot] = key, parent
                    self._n += 1
            stored.append(new)
        return np.array(stored, dtype=np.bool_)

    def put(self, key: int, parent: int) -> None:
        """Store one key (`parent` ROOT for an initial world) unless it is stored."""
        self.add(np.array([key], dtype=np.uint64), np.array([max(parent, 0)], dtype=np.uint64))

    def get(self, key: int) -> int | None:
        """The parent key of `key` (ROOT for an initial world), or None if not stored."""
        if key == 0:
            parent = self._zero
        else:
            slot, found = self._slot(key)
            parent = int(self._parents[slot]) if found else None
        return None if parent is None else (ROOT if parent == 0 else parent)

    def __contains__(self, key: int) -> bool:
        return self.get(key) is not None

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """Every stored key and its parent key (0 for an initial world), in slot order."""
        used = self._keys != _EMPTY
        keys, parents = self._keys[used], self._parents[used]
        if self._zero is not None:
            keys = np.append(keys, _EMPTY)
            parents = np.append(parents, np.uint64(self._zero))
        return keys, parents

    def nbytes(self) -> int:
        """Bytes held by the two arrays."""
        return int(self._keys.nbytes + self._parents.nbytes)

    def _grow_for(self, count: int) -> None:
        capacity = len(self._keys)
        if count <= capacity * _MAX_LOAD:
            return
        while count > capacity * _MAX_LOAD:
            capacity *= 2
        used = self._keys != _EMPTY
        keys, parents = self._keys[used], self._parents[used]
        self._keys = np.zeros(capacity, dtype=np.uint64)
        self._parents = np.zeros(capacity, dtype=np.uint64)
        self._mask = np.uint64(capacity - 1)
        self._n = 0
        for first in range(0, len(keys), _CHUNK):
            self._place(keys[first:first + _CHUNK], parents[first:first + _CHUNK])

    def _place(self, keys: np.ndarray, parents: np.ndarray) -> None:
        """Enter distinct keys, none stored nor 0, into free slots: in each probing round
        one key per free slot wins, the others probe on."""
        table, mask = self._keys, self._mask
        slots = keys & mask
        todo = np.arange(len(keys))
        while len(todo):
            cand = slots[todo]
            free = table[cand] == _EMPTY
            uniq, pick = np.unique(cand[free], return_index=True)
            winners = todo[free][pick]
            table[uniq] = keys[winners]
            self._parents[uniq] = parents[winners]
            placed = np.zeros(len(keys), dtype=np.bool_)
            placed[winners] = True
            todo = todo[~placed[todo]]
            slots[todo] = (slots[todo] + np.uint64(1)) & mask
        self._n += len(keys)


def _probe(table: memoryview, mask: int, key: int) -> tuple[int, bool]:
    """Linear probing for one key (not 0) in Python, on a view of the keys' array (a view
    reads a slot as a Python int, where the array would make a numpy scalar): its slot,
    or the empty slot where it would go, and whether it is there."""
    slot = key & mask
    while (held := table[slot]) != key:
        if not held:
            return slot, False
        slot = (slot + 1) & mask
    return slot, True
