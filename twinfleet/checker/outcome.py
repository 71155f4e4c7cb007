"""What a search reports, and what stops it: limits, counters, counterexamples, verdicts.

`Guard` decides when a search stops early (Ctrl-C, `max_time_s`,
`max_states`) and when it reports progress; every search (`checker.search`,
`checker.walks`) checks it between two expansions. A search that finds a
violation raises `Found` with the `Counterexample` that leads to it; one that
must stop raises `Stop`; both are caught by `Search.run`, which turns them
into an `Outcome`.
"""

from __future__ import annotations

import resource
import signal
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, final

from twinfleet.checker.growth import GrowthNote
from twinfleet.checker.properties import PropertyViolation
from twinfleet.checker.transition import Step
from twinfleet.runtime.contract.kinds import Status

# Why a search stopped on Ctrl-C (its status is then `Status.UNKNOWN`).
INTERRUPTED_REASON = "interrupted (Ctrl-C)"


@final
@dataclass(frozen=True, slots=True)
class Limits:
    """Search limits; None means unlimited."""

    max_states: int | None = None
    max_time_s: float | None = None
    max_depth: int | None = None


NO_LIMITS = Limits()


@final
@dataclass(frozen=True, slots=True)
class SearchStatistics:
    """A frozen record of the search's counters.

    `store_bytes` is what the visited-state store holds (digest index, parents,
    flags, edges); `collision_probability` the estimated chance that two
    different states were merged by their digests (see `checker.store`).
    """

    states: int
    transitions: int
    initial_states: int
    depth: int
    frontier: int
    elapsed_s: float
    peak_rss_mb: float
    store_bytes: int = 0
    digest_bits: int = 64
    collision_probability: float = 0.0
    peak_frontier: int = 0
    attempt_s: float | None = None  # seconds since a reduced search last started again
    restarts: int = 0  # times a reduced search started again from scratch (counts reset)
    growth: tuple[GrowthNote, ...] = ()  # fields that keep taking new values (checker.growth)

    @property
    def attempt_transitions_per_s(self) -> float:
        """Transitions per second of the search's last attempt: a reduced search that
        learned a send started again from scratch and counts only what it did since
        (`attempt_s`); the whole run when it never started again."""
        seconds = self.elapsed_s if self.attempt_s is None else self.attempt_s
        return self.transitions / seconds if seconds > 0 else 0.0

    @property
    def states_per_s(self) -> float:
        """Distinct states found per second of wall time."""
        return self.states / self.elapsed_s if self.elapsed_s > 0 else 0.0

    @property
    def transitions_per_s(self) -> float:
        """Transitions executed per second of wall time."""
        return self.transitions / self.elapsed_s if self.elapsed_s > 0 else 0.0

    @property
    def bytes_per_state(self) -> float:
        """Store bytes per visited state."""
        return self.store_bytes / self.states if self.states else 0.0


@final
@dataclass(slots=True)
class Counters:
    """The running counts of one search (`transitions`: every step taken, revisits
    included; `depth`: the deepest world found, in steps)."""

    transitions: int = 0
    initial: int = 0
    depth: int = 0
    peak_frontier: int = 0


@final
@dataclass(frozen=True, slots=True)
class Counterexample:
    """Initial-world choices, then the steps to a violation; a lasso's last step returns
    to the world after `cycle_start` steps (None: the path ends in its last world)."""

    initial: tuple[int, ...]
    steps: tuple[Step, ...]
    cycle_start: int | None = None


@final
@dataclass(slots=True)
class Outcome:
    """What a search concluded."""

    status: Status  # HOLDS, VIOLATED or UNKNOWN
    reason: str
    statistics: SearchStatistics
    violation: PropertyViolation | None = None
    counterexample: Counterexample | None = None
    checkpoint: str | None = None  # the checkpoint file written when the search stopped early


class Stop(Exception):
    """The search must stop before a verdict (a limit, Ctrl-C)."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


class Found(Exception):
    """The search found a violation."""

    def __init__(self, violation: PropertyViolation, counterexample: Counterexample) -> None:
        super().__init__(violation.message)
        self.violation = violation
        self.counterexample = counterexample


def peak_rss_mb() -> float:
    """Peak resident memory of this process in MB."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


@final
class Guard:
    """Ctrl-C, the time and state limits and progress reports of one search.

    Args:
        limits: the search's limits.
        progress: called with statistics at most every `interval` seconds.
        interval: seconds between two progress reports.
        handle_sigint: stop cleanly on the first Ctrl-C (main thread only).
    """

    def __init__(self, limits: Limits, progress: Callable[[SearchStatistics], None] | None,
                 interval: float, handle_sigint: bool) -> None:
        self.limits = limits
        self._progress = progress
        self._interval = interval
        self._handle_sigint = handle_sigint
        self._sigint = False
        self.started = self._last_report = time.monotonic()

    def restart_clock(self) -> None:
        """The search (re)starts now: time limits and reports count from here."""
        self.started = self._last_report = time.monotonic()

    @contextmanager
    def sigint_handler(self) -> Iterator[None]:
        """First Ctrl-C: stop at the next step boundary; second: interrupt at once."""
        if not self._handle_sigint or threading.current_thread() is not threading.main_thread():
            yield
            return

        def on_sigint(signum: int, frame: Any) -> None:
            if self._sigint:
                raise KeyboardInterrupt
            self._sigint = True

        previous = signal.signal(signal.SIGINT, on_sigint)
        try:
            yield
        finally:
            signal.signal(signal.SIGINT, previous)

    def tick(self, statistics: Callable[[], SearchStatistics]) -> None:
        """Between two expansions: raise `Stop` on Ctrl-C or the time limit; report."""
        now = time.monotonic()
        if self._sigint:
            raise Stop(INTERRUPTED_REASON)
        limit = self.limits.max_time_s
        if limit is not None and now - self.started >= limit:
            raise Stop(f"max-time {limit:g} s reached before the search finished")
        if self._progress is not None and now - self._last_report >= self._interval:
            self._last_report = now
            try:
                self._progress(statistics())
            except KeyboardInterrupt:
                raise Stop(INTERRUPTED_REASON) from None

    def count_states(self, states: int) -> None:
        """After a new state: raise `Stop` when the state limit is reached."""
        limit = self.limits.max_states
        if limit is not None and states >= limit:
            raise Stop(f"max-states {limit} reached before the search finished")
