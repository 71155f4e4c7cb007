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
from dataclasses import dataclass
from typing import NamedTuple, Protocol, final

from twinfleet.runtime.contract.context import Chooser


@final
class LatencySite(NamedTuple):
    """What a latency branch decides: the delay of one message on `channel` (a topic or
    service), `low + index` ms. Exhaustive choosers ignore it; a chooser that samples
    from a timing model (`checker.sampling`) weighs the indices by it. (A named tuple:
    one is built per message sent.)"""

    channel: str
    low: int
    sent: int | None = None  # the fleet ms the message was sent at
    #: which publish of its handler run the message is a copy of (its effect's index;
    #: None for a request or reply): one publish's deliveries share part of their delay
    publish: int | None = None


@final
@dataclass(frozen=True, slots=True)
class LatenessSite:
    """What a timer-lateness branch decides: the next tick of an `@every` timer, branch k
    being taken for a lateness from `least[k]` ms up to `least[k + 1]` (the last up to
    any). Exhaustive choosers ignore it; a sampling chooser weighs the branches by the
    timing model's timer lateness."""

    least: tuple[int, ...]


Site = LatencySite | LatenessSite  # what a sampling chooser weighs a branch by


class ExploringChooser(Chooser, Protocol):
    """A `Chooser` (what answers `ctx.choose`) that the checker explores with: `branch`
    for the checker's own branches on its effects (latency, drop, duplicate), the
    answers given so far in call order, and `mismatch`: the `ChoiceMismatch` raised when
    a forced answer did not exist (a handler may catch the exception; the chooser keeps
    it, so the checker still knows)."""

    indices: list[int]
    options: list[int]
    mismatch: ChoiceMismatch | None

    def choose(self, n: int) -> int:
        """An index in range(n) for a handler's choice point."""
        ...

    def branch(self, n: int, site: Site | None = None) -> int:
        """An index in range(n) for one of the checker's branches (`site`: a latency's or a timer's)."""
        ...


@final
class PrefixChooser:
    """Answers `choose(n)` from a forced prefix of indices, then with 0.

    Attributes:
        indices: every index returned so far (only for choice points with n > 1).
        options: the number of options each of those choice points had.
    """

    __slots__ = ("_prefix", "indices", "mismatch", "options")

    def __init__(self, prefix: Sequence[int] = ()) -> None:
        self._prefix = tuple(prefix)
        self.indices: list[int] = []
        self.options: list[int] = []
        self.mismatch: ChoiceMismatch | None = None

    def choose(self, n: int) -> int:
        """Return the forced index of this choice point, or 0 past the prefix."""
        k = len(self.indices)
        index = self._prefix[k] if k < len(self._prefix) else 0
        if not 0 <= index < n:
            self.mismatch = ChoiceMismatch(k, n, index)
            raise self.mismatch
        self.indices.append(index)
        self.options.append(n)
        return index

    def branch(self, n: int, site: Site | None = None) -> int:
        """The checker's own branches (latency, faults) are choice points too."""
        return self.choose(n)

    def next_prefix(self) -> tuple[int, ...] | None:
        """The prefix of the next variant after this run, or None if this was the last."""
        return _odometer(self.indices, self.options)


def _odometer(indices: Sequence[int], options: Sequence[int]) -> tuple[int, ...] | None:
    """The next prefix after `indices` (each below its `options`), or None after the last."""
    for k in range(len(indices) - 1, -1, -1):
        if indices[k] + 1 < options[k]:
            return (*indices[:k], indices[k] + 1)
    return None


@final
class SplitChooser:
    """Answers a handler's `choose(n)` from recorded answers and the checker's own
    `branch(n)` (latency, drop, duplicate) from a prefix, then 0 — for checking a live
    run, whose log holds the handlers' answers but not the checker's branches.

    Records every answer in call order (`indices`, `options`, like PrefixChooser) and
    the handlers' and branches' answers apart; `next_branch_prefix` enumerates the
    branches like an odometer, the handlers' answers staying as recorded.
    """

    __slots__ = ("_answers", "_prefix", "branch_indices", "branch_options", "handler_indices",
                 "handler_options", "indices", "mismatch", "options")

    def __init__(self, answers: Sequence[int], branch_prefix: Sequence[int] = ()) -> None:
        self._answers, self._prefix = tuple(answers), tuple(branch_prefix)
        self.indices: list[int] = []
        self.options: list[int] = []
        self.handler_indices: list[int] = []
        self.handler_options: list[int] = []
        self.branch_indices: list[int] = []
        self.branch_options: list[int] = []
        self.mismatch: ChoiceMismatch | None = None

    def choose(self, n: int) -> int:
        """The recorded answer of this handler choice point (0 past the record)."""
        return self._answer(n, self._answers, self.handler_indices, self.handler_options)

    def branch(self, n: int, site: Site | None = None) -> int:
        """The forced index of this branch of the checker (0 past the prefix)."""
        return self._answer(n, self._prefix, self.branch_indices, self.branch_options)

    def _answer(self, n: int, forced: tuple[int, ...], indices: list[int],
                options: list[int]) -> int:
        k = len(indices)
        index = forced[k] if k < len(forced) else 0
        if not 0 <= index < n:
            self.mismatch = ChoiceMismatch(k, n, index)
            raise self.mismatch
        indices.append(index)
        options.append(n)
        self.indices.append(index)
        self.options.append(n)
        return index

    def next_branch_prefix(self) -> tuple[int, ...] | None:
        """The branch prefix of the next variant with the same handler answers, or None."""
        return _odometer(self.branch_indices, self.branch_options)


@final
class RandomChooser:
    """Answers `choose(n)` uniformly from a seeded RNG, recording like PrefixChooser."""

    __slots__ = ("_rng", "indices", "mismatch", "options")

    def __init__(self, rng: random.Random) -> None:
        self._rng = rng
        self.indices: list[int] = []
        self.options: list[int] = []
        self.mismatch: ChoiceMismatch | None = None  # never: every answer exists

    def choose(self, n: int) -> int:
        """Return a random index in range(n)."""
        index = self._rng.randrange(n)
        self.indices.append(index)
        self.options.append(n)
        return index

    def branch(self, n: int, site: Site | None = None) -> int:
        """A uniform index for one of the checker's branches."""
        return self.choose(n)


class ChoiceMismatch(ValueError):
    """A forced choice does not exist in this run (the handler chose differently).

    Attributes:
        point: the choice point (0-based, in call order).
        options: how many options it had.
        index: the index that was forced.
    """

    def __init__(self, point: int, options: int, index: int) -> None:
        super().__init__(f"choice point {point} has {options} options, cannot force "
                         f"index {index}")
        self.point, self.options, self.index = point, options, index
