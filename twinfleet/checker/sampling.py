"""`SamplingChooser`: answers every choice point of a simulation by a draw.

A handler's `ctx.choose(options)` is drawn uniformly; the checker's latency
branches (`checker.choices.LatencySite`) are drawn from the timing model's
histogram of their channel (of the start-up, for a message sent in the model's
start-up window), restricted to the branch's range; its other
branches (drop, duplicate, no server) uniformly. Every answer is recorded as an
index, as `PrefixChooser` records them, so a simulation's steps are ordinary
trace steps that `twinfleet replay` re-takes.
"""

from __future__ import annotations

import random
from bisect import bisect_right
from itertools import accumulate
from typing import final

from twinfleet.checker.choices import ChoiceMismatch, LatencySite
from twinfleet.checker.timing import TimingModel


@final
class SamplingChooser:
    """Draws answers from `rng`: latencies by `model`, everything else uniformly."""

    __slots__ = ("_cumulative", "_model", "_rng", "indices", "mismatch", "options")

    def __init__(self, rng: random.Random, model: TimingModel,
                 cumulative: dict[tuple[str, int, int, bool], list[float]] | None = None
                 ) -> None:
        self._rng, self._model = rng, model
        #: cumulative weights per (channel, low, n, start-up): shared by one run's choosers
        self._cumulative = {} if cumulative is None else cumulative
        self.indices: list[int] = []
        self.options: list[int] = []
        self.mismatch: ChoiceMismatch | None = None  # never: every answer exists

    def choose(self, n: int) -> int:
        """A uniform index in range(n)."""
        index = self._rng.randrange(n)
        self.indices.append(index)
        self.options.append(n)
        return index

    def branch(self, n: int, site: LatencySite | None = None) -> int:
        """A latency's index drawn from the model; any other branch uniformly."""
        if site is None:
            return self.choose(n)
        model = self._model
        key = (site.channel, site.low, n, model.starting(site.sent))
        cum = self._cumulative.get(key)
        if cum is None:
            weights = model.latency_of(site.channel, site.sent).weights_over(site.low, n)
            cum = self._cumulative[key] = list(accumulate(weights))
        index = min(bisect_right(cum, self._rng.random() * cum[-1]), n - 1)
        self.indices.append(index)
        self.options.append(n)
        return index
