"""Estimating a probability from independent simulations: intervals and Wald's SPRT.

Pure arithmetic on counts (no scipy): `clopper_pearson` is the exact binomial
interval, found by bisection on the regularized incomplete beta function
(its continued fraction, evaluated by the modified Lentz method): a few
milliseconds, so progress lines show it too. `Sprt` is Wald's
sequential probability ratio test of "the probability is below `bound`"
with an indifference region [`bound` - `indifference`, `bound`]:

- `alpha`: the probability of accepting "below" although p >= bound (a wrong
  sign-off);
- `beta`: the probability of refusing although p <= bound - indifference.

`binomial_test` is the exact two-sided test of "k successes in n trials come
from probability p"; `agreement_p_value` extends it to a p known only up to a
confidence interval (how `twinfleet experiment` holds a live frequency against
a predicted interval).

With H_safe: p = p0 = bound - indifference and H_unsafe: p = p1 = bound, the
log-likelihood ratio L = sum log(f_unsafe / f_safe) over the outcomes is
compared after each one with log(alpha / (1 - beta)) (accept "below") and
log((1 - alpha) / beta) (refuse). Wald's bounds hold for any p outside the
indifference region; inside it either answer is acceptable.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum
from typing import final


def _betacf(a: float, b: float, x: float) -> float:
    """The continued fraction of the incomplete beta function (modified Lentz)."""
    tiny, eps = 1e-300, 1e-15
    qab, qap, qam = a + b, a + 1.0, a - 1.0
    c, d = 1.0, 1.0 - qab * x / qap
    d = 1.0 / (d if abs(d) > tiny else tiny)
    h = d
    for m in range(1, 10_000):
        m2 = 2 * m
        aa = m * (b - m) * x / ((qam + m2) * (a + m2))
        d = 1.0 + aa * d
        d = 1.0 / (d if abs(d) > tiny else tiny)
        c = 1.0 + aa / c
        c = c if abs(c) > tiny else tiny
        h *= d * c
        aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2))
        d = 1.0 + aa * d
        d = 1.0 / (d if abs(d) > tiny else tiny)
        c = 1.0 + aa / c
        c = c if abs(c) > tiny else tiny
        step = d * c
        h *= step
        if abs(step - 1.0) < eps:
            break
    return h


def betainc(a: float, b: float, x: float) -> float:
    """The regularized incomplete beta function I_x(a, b), for a, b > 0 and 0 <= x <= 1."""
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    log_front = (math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b)
                 + a * math.log(x) + b * math.log1p(-x))
    if x < (a + 1.0) / (a + b + 2.0):
        return math.exp(log_front) * _betacf(a, b, x) / a
    return 1.0 - math.exp(log_front) * _betacf(b, a, 1.0 - x) / b


def beta_quantile(q: float, a: float, b: float) -> float:
    """The x with I_x(a, b) = q (bisection to 1e-12)."""
    low, high = 0.0, 1.0
    for _ in range(60):
        mid = (low + high) / 2
        if betainc(a, b, mid) < q:
            low = mid
        else:
            high = mid
    return (low + high) / 2


def clopper_pearson(k: int, n: int, confidence: float) -> tuple[float, float]:
    """The exact (Clopper–Pearson) interval for p after `k` successes in `n` trials."""
    if n == 0:
        return 0.0, 1.0
    tail = (1.0 - confidence) / 2
    low = 0.0 if k == 0 else beta_quantile(tail, k, n - k + 1)
    high = 1.0 if k == n else beta_quantile(1.0 - tail, k + 1, n - k)
    return low, high


def binomial_test(k: int, n: int, p: float) -> float:
    """The exact two-sided binomial p-value of `k` successes in `n` trials under probability
    `p`: the total probability of every outcome no more likely than `k`."""
    if n == 0:
        return 1.0
    if p <= 0.0 or p >= 1.0:
        return 1.0 if k == (0 if p <= 0.0 else n) else 0.0
    logs = [math.lgamma(n + 1) - math.lgamma(j + 1) - math.lgamma(n - j + 1)
            + j * math.log(p) + (n - j) * math.log1p(-p) for j in range(n + 1)]
    # Outcomes as likely as k up to rounding count as "no more likely" (the usual relative
    # tolerance of exact tests), so that a symmetric case gives exactly 1.
    edge = logs[k] + 1e-7
    return min(1.0, math.fsum(math.exp(x) for x in logs if x <= edge))


def agreement_p_value(k: int, n: int, low: float, high: float, confidence: float) -> float:
    """How well `k` of `n` agrees with a probability known to lie in [`low`, `high`] at
    `confidence`: the largest `binomial_test` p-value over the interval, plus the interval's
    own error 1 - `confidence` (Berger and Boos's p-value for a nuisance parameter known up
    to a confidence set, 1994), at most 1. Small: the counts and the interval disagree."""
    if n == 0:
        return 1.0
    if low <= k / n <= high:
        return 1.0
    grid = [low + (high - low) * i / 200 for i in range(201)]
    return min(1.0, max(binomial_test(k, n, p) for p in grid) + (1.0 - confidence))


class Decision(Enum):
    """Where a sequential test stands."""

    UNDECIDED = "undecided"
    BELOW = "below"          # accepted: the probability is below the bound
    NOT_BELOW = "not below"  # refused: it is not


@final
@dataclass(slots=True)
class Sprt:
    """Wald's sequential probability ratio test (module docstring); feed outcomes in order."""

    bound: float
    indifference: float
    alpha: float = 0.01
    beta: float = 0.01
    llr: float = 0.0
    n: int = 0
    k: int = 0

    def __post_init__(self) -> None:
        p0, p1 = self.bound - self.indifference, self.bound
        if not (0 < p0 < p1 < 1):
            raise ValueError(f"need 0 < bound - indifference < bound < 1, got bound "
                             f"{self.bound:g}, indifference {self.indifference:g}")
        if not (0 < self.alpha < 0.5 and 0 < self.beta < 0.5):
            raise ValueError("alpha and beta must lie in (0, 0.5)")

    @property
    def accept_below(self) -> float:
        """The log-ratio at or under which "below" is accepted."""
        return math.log(self.alpha / (1 - self.beta))

    @property
    def refuse(self) -> float:
        """The log-ratio at or over which "below" is refused."""
        return math.log((1 - self.alpha) / self.beta)

    def add(self, violated: bool) -> Decision:
        """Take one outcome; the decision so far."""
        p0, p1 = self.bound - self.indifference, self.bound
        self.n += 1
        if violated:
            self.k += 1
            self.llr += math.log(p1 / p0)
        else:
            self.llr += math.log((1 - p1) / (1 - p0))
        return self.decision

    @property
    def decision(self) -> Decision:
        """BELOW, NOT_BELOW or UNDECIDED on the outcomes so far."""
        if self.llr <= self.accept_below:
            return Decision.BELOW
        if self.llr >= self.refuse:
            return Decision.NOT_BELOW
        return Decision.UNDECIDED
