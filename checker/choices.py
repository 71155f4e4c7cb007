"""Choosers that let the checker enumerate, force or sample `ctx.choose`.

A handler is re-run from the same restored state once per combination of
choice indices. `PrefixChooser` answers the first choice points from a forced
prefix and 0 afterwards, recording how many options each point had; the next
prefix is the previous run's indices advanced like an odometer. The recorded
`(indices, options)` of one run identify its variant exactly, and replaying
with `PrefixChooser(indices)` reproduces it.
"""

from __future__ import annotations

import random
from collections.abc import Sequence
from typing import final


@final
class PrefixChooser:
    """Answers `choose(n)` from a forced prefix of indices, then with 0.

    Attributes:
        indices: every index returned so far (only for choice points with n > 1).
        options: the number of options each of those choice points had.
    """

    __slots__ = ("_prefix", "indices", "options")

    def __init__(self, prefix: Sequence[int] = ()) -> None:
        self._prefix = tuple(prefix)
        self.indices: list[int] = []
        self.options: list[int] = []

    def choose(self, n: int) -> int:
        """Return the forced index of this choice point, or 0 past the prefix."""
        k = len(self.indices)
        index = self._prefix[k] if k < len(self._prefix) else 0
        if not 0 <= index < n:
            raise ChoiceMismatch(f"choice point {k} has {n} options, cannot force index {index}")
        self.indices.append(index)
        self.options.append(n)
        return index

    def next_prefix(self) -> tuple[int, ...] | None:
        """The prefix of the next variant after this run, or None if this was the last."""
        for k in range(len(self.indices) - 1, -1, -1):
            if self.indices[k] + 1 < self.options[k]:
                return (*self.indices[:k], self.indices[k] + 1)
        return None


@final
class RandomChooser:
    """Answers `choose(n)` uniformly from a seeded RNG, recording like PrefixChooser."""

    __slots__ = ("_rng", "indices", "options")

    def __init__(self, rng: random.Random) -> None:
        self._rng = rng
        self.indices: list[int] = []
        self.options: list[int] = []

    def choose(self, n: int) -> int:
        """Return a random index in range(n)."""
        index = self._rng.randrange(n)
        self.indices.append(index)
        self.options.append(n)
        return index


class ChoiceMismatch(ValueError):
    """A forced choice does not exist in this run (the handler chose differently)."""
