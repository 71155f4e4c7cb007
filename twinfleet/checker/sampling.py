"""`SamplingChooser`: answers every choice point of a simulation by a draw.

A handler's `ctx.choose(options)` is drawn uniformly; the checker's latency
branches (`checker.choices.LatencySite`) are drawn from the timing model's
histogram of their channel (of the start-up, for a message sent in the model's
start-up window), restricted to the branch's range, the copies of one publish
through a Gaussian copula with the model's `together` correlation (one common
normal draw per publish, one own per copy: each copy keeps its histogram); a
timer's next tick (`checker.choices.LatenessSite`) by the weight the model's timer
lateness gives each branch's span of lateness; its other
branches (drop, duplicate, no server) uniformly. Every answer is recorded as an
index, as `PrefixChooser` records them, so a simulation's steps are ordinary
trace steps that `twinfleet replay` re-takes.
"""

from __future__ import annotations

import math
import random
from bisect import bisect_right
from itertools import accumulate
from typing import final

from twinfleet.checker.choices import ChoiceMismatch, LatenessSite, Site
from twinfleet.checker.timing import Histogram, TimingModel


@final
class SamplingChooser:
    """Draws answers from `rng`: latencies by `model`, everything else uniformly."""

    __slots__ = ("_common", "_cumulative", "_model", "_rng", "indices", "mismatch", "options")

    def __init__(self, rng: random.Random, model: TimingModel,
                 cumulative: dict[tuple[str, int, int, bool], tuple[list[float], float]]
                 | None = None) -> None:
        self._rng, self._model = rng, model
        #: (cumulative weights, copula correlation) per (channel, low, n, start-up): shared
        #: by one run's choosers
        self._cumulative = {} if cumulative is None else cumulative
        self._common: dict[int, float] = {}  # the common normal draw of each publish
        self.indices: list[int] = []
        self.options: list[int] = []
        self.mismatch: ChoiceMismatch | None = None  # never: every answer exists

    def choose(self, n: int) -> int:
        """A uniform index in range(n)."""
        index = self._rng.randrange(n)
        self.indices.append(index)
        self.options.append(n)
        return index

    def branch(self, n: int, site: Site | None = None) -> int:
        """A latency's or a timer's index drawn from the model; any other branch uniformly."""
        if site is None:
            return self.choose(n)
        if isinstance(site, LatenessSite):
            return self._late_tick(n, site)
        model = self._model
        key = (site.channel, site.low, n, model.starting(site.sent))
        found = self._cumulative.get(key)
        if found is None:
            weights = model.latency_of(site.channel, site.sent).weights_over(site.low, n)
            found = self._cumulative[key] = (list(accumulate(weights)),
                                             model.together_of(site.channel))
        cum, rho = found
        if rho and site.publish is not None:
            u = self._copula(site.publish, rho)
        else:
            u = self._rng.random()
        index = min(bisect_right(cum, u * cum[-1]), n - 1)
        self.indices.append(index)
        self.options.append(n)
        return index

    def _copula(self, publish: int, rho: float) -> float:
        """A uniform draw for one copy of publish `publish`: the normal CDF of its
        publish's common draw and its own, mixed to correlation `rho`."""
        common = self._common.get(publish)
        if common is None:
            common = self._common[publish] = self._rng.gauss(0.0, 1.0)
        z = math.sqrt(rho) * common + math.sqrt(1.0 - rho) * self._rng.gauss(0.0, 1.0)
        return 0.5 * (1.0 + math.erf(z / math.sqrt(2.0)))

    def _late_tick(self, n: int, site: LatenessSite) -> int:
        """A timer's next tick (Rule 7), drawn by the model's timer lateness."""
        cum = list(accumulate(_spans(self._model.timer_lateness, site.least)))
        if not cum[-1]:  # the model gives none of these a weight: uniform
            cum = list(accumulate([1.0] * n))
        index = min(bisect_right(cum, self._rng.random() * cum[-1]), n - 1)
        self.indices.append(index)
        self.options.append(n)
        return index


def _spans(lateness: Histogram, least: tuple[int, ...]) -> list[float]:
    """The weight `lateness` gives each span ``least[k] <= L < least[k + 1]`` (the last
    span unbounded above)."""
    ends = (*least[1:], None)
    pairs = list(zip(lateness.values, lateness.weights, strict=True))
    return [sum(w for v, w in pairs if low <= v and (end is None or v < end))
            for low, end in zip(least, ends, strict=True)]
