"""The live answers to `ctx.choose`: a seeded random chooser, and one that records.

A live node answers `ctx.choose` from a `random.Random` seeded per node with
`derive_seed(fleet_seed, node_name)`, stable across processes and
``PYTHONHASHSEED`` values. A `RecordingChooser` answers forced indices first
(a replay grant's choices), then asks an inner chooser, and keeps every answer
with its option count — the checker's ``Step.choices``/``options`` — for the
event log and the replay gate.
"""

from __future__ import annotations

import hashlib
import random
from collections.abc import Sequence
from typing import final

from twinfleet.runtime.contract.context import Chooser


def derive_seed(seed: int, node_name: str) -> int:
    """A per-node seed that is stable across processes and PYTHONHASHSEED values."""
    digest = hashlib.sha256(f"{seed}:{node_name}".encode()).digest()
    return int.from_bytes(digest[:8], "big")


@final
class SeededChooser:
    """Answers `ctx.choose` live from a seeded `random.Random`."""

    def __init__(self, seed: int) -> None:
        self._rng = random.Random(seed)

    def choose(self, n: int) -> int:
        """A uniformly random index in range(n)."""
        return self._rng.randrange(n)


@final
class RecordingChooser:
    """Answers `ctx.choose` with `forced` indices first, then from `inner` (or 0), and
    records every answer and how many options it had (the checker's `Step.choices/options`)."""

    __slots__ = ("forced", "indices", "inner", "options")

    def __init__(self, inner: Chooser | None, forced: Sequence[int] = ()) -> None:
        self.inner, self.forced = inner, tuple(forced)
        self.indices: list[int] = []
        self.options: list[int] = []

    def choose(self, n: int) -> int:
        """The forced index of this choice point, else `inner`'s answer, else 0."""
        k = len(self.indices)
        if k < len(self.forced):
            index = self.forced[k]
        else:
            index = self.inner.choose(n) if self.inner is not None else 0
        self.indices.append(index)
        self.options.append(n)
        if not 0 <= index < n:
            raise ValueError(f"choice point {k} has {n} options, cannot answer {index}")
        return index
