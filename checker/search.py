"""State-space search: BFS, DFS, random walks, and the lasso search for liveness.

`Search.run("bfs")` explores breadth-first, so the first violation found has
a shortest trace; "dfs" pops the newest world first (less memory on deep
spaces); both check every safety property on every new world and every
handler failure on every transition, and stop at the first violation. Visited
states live in a `checker.graph.StateGraph`; when the scenario has
`eventually` properties it also records every edge, and once the safety search
is complete each of them is checked on that graph by `find_lasso` (no handler
is re-run). "random" runs seeded random walks instead and can only find
violations, never prove their absence.

Counters (`SearchStatistics`): `states` are distinct world digests and
`transitions` every handler run (one per choice variant, revisits included).
"""

from __future__ import annotations

import random
import resource
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import final

from checker.choices import RandomChooser
from checker.graph import StateGraph, find_lasso, steps_along
from checker.properties import Property, PropertySet, Violation
from checker.system import Step, System, Transition
from checker.world import World

HOLDS, VIOLATED, UNKNOWN = "holds", "violated", "unknown"


@final
@dataclass(frozen=True, slots=True)
class Limits:
    """Search limits; None means unlimited."""

    max_states: int | None = None
    max_time_s: float | None = None
    max_depth: int | None = None


@final
@dataclass(frozen=True, slots=True)
class SearchStatistics:
    """A frozen record of the search's counters."""

    states: int
    transitions: int
    initial_states: int
    depth: int
    frontier: int
    elapsed_s: float
    peak_rss_mb: float

    @property
    def states_per_s(self) -> float:
        """Distinct states found per second of wall time."""
        return self.states / self.elapsed_s if self.elapsed_s > 0 else 0.0

    @property
    def transitions_per_s(self) -> float:
        """Transitions executed per second of wall time."""
        return self.transitions / self.elapsed_s if self.elapsed_s > 0 else 0.0


@final
@dataclass(frozen=True, slots=True)
class Path:
    """A counterexample: initial-world choices, then steps; lassos loop back to `cycle_start`."""

    initial: tuple[int, ...]
    steps: tuple[Step, ...]
    cycle_start: int | None = None


@final
@dataclass(slots=True)
class Outcome:
    """What a search concluded."""

    status: str  # HOLDS, VIOLATED or UNKNOWN
    reason: str
    statistics: SearchStatistics
    violation: Violation | None = None
    path: Path | None = None


class _Stop(Exception):
    def __init__(self, reason: str) -> None:
        self.reason = reason


class _Found(Exception):
    def __init__(self, violation: Violation, path: Path) -> None:
        self.violation = violation
        self.path = path


def peak_rss_mb() -> float:
    """Peak resident memory of this process in MB."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


@final
class Search:
    """One search over a `System` for a `PropertySet`.

    Args:
        system: the compiled scenario.
        properties: what to check.
        limits: state, time and depth limits.
        progress: called with statistics at most every `progress_interval` seconds.
    """

    def __init__(self, system: System, properties: PropertySet, limits: Limits = Limits(), *,
                 progress: Callable[[SearchStatistics], None] | None = None,
                 progress_interval: float = 1.0) -> None:
        self.system = system
        self.properties = properties
        self.limits = limits
        self._progress = progress
        self._interval = progress_interval
        live = tuple(p.name for p in properties.eventually)
        self.graph = StateGraph(record_edges=bool(live), flags=live)
        self._frontier: deque[tuple[World, int, int]] = deque()
        self._transitions = 0
        self._initial = 0
        self._depth = 0
        self._pruned = False
        self._start = time.monotonic()
        self._last_report = self._start

    def statistics(self) -> SearchStatistics:
        """The counters so far."""
        return SearchStatistics(len(self.graph), self._transitions, self._initial, self._depth,
                                len(self._frontier), time.monotonic() - self._start,
                                peak_rss_mb())

    def run(self, strategy: str = "bfs", *, walks: int = 100, seed: int = 0) -> Outcome:
        """Search with `strategy` ("bfs", "dfs" or "random") until a verdict or a limit."""
        self._start = self._last_report = time.monotonic()
        try:
            if strategy == "random":
                return self._random(walks, seed)
            if strategy not in ("bfs", "dfs"):
                raise ValueError(f"unknown search strategy {strategy!r}")
            self._explore(lifo=strategy == "dfs")
            if self._pruned:
                return self._outcome(UNKNOWN, f"max-depth {self.limits.max_depth} reached "
                                     "before the search finished")
            for prop in self.properties.eventually:
                self._lasso(prop)
            return self._outcome(HOLDS, "every property holds")
        except _Found as found:
            return self._outcome(VIOLATED, found.violation.property, found.violation, found.path)
        except _Stop as stop:
            return self._outcome(UNKNOWN, stop.reason)
        except KeyboardInterrupt:
            return self._outcome(UNKNOWN, "interrupted (Ctrl-C)")

    def _outcome(self, status: str, reason: str, violation: Violation | None = None,
                 path: Path | None = None) -> Outcome:
        return Outcome(status, reason, self.statistics(), violation, path)

    # -------------------------------------------------------- safety search

    def _explore(self, *, lifo: bool) -> None:
        max_depth = self.limits.max_depth
        edges = self.graph.edges
        for init in self.system.initial():
            self._initial += 1
            self._discover(init, -1, 0)
        frontier = self._frontier
        pop = frontier.pop if lifo else frontier.popleft
        while frontier:
            world, sid, depth = pop()
            if max_depth is not None and depth >= max_depth:
                self._pruned = True
                continue
            for t in self.system.successors(world):
                self._transitions += 1
                child = self._discover(t, sid, depth + 1)
                if edges is not None:
                    edges[sid].append(child)
            self._tick()

    def _discover(self, t: Transition, parent: int, depth: int) -> int:
        if t.failure is not None:
            raise _Found(self.properties.check_failure(t.failure), self._path_to(parent, t))
        world = t.world
        sid, new = self.graph.add(world.digest, parent, terminal=world.terminal)
        if not new:
            return sid
        if parent < 0:
            self.graph.roots[sid] = t.step.choices
        if depth > self._depth:
            self._depth = depth
        for name, bits in self.graph.holds.items():
            bits.append(self._holds(self.properties.eventually_named(name), world))
        violation = self.properties.check_world(self.system, world)
        if violation is not None:
            raise _Found(violation, self._path_to(sid))
        self._frontier.append((world, sid, depth))
        if self.limits.max_states is not None and len(self.graph) >= self.limits.max_states:
            raise _Stop(f"max-states {self.limits.max_states} reached before the search finished")
        return sid

    def _path_to(self, sid: int, failing: Transition | None = None) -> Path:
        if sid < 0:  # a start handler failed: no steps
            assert failing is not None
            return Path(failing.step.choices, ())
        initial, steps = steps_along(self.system, self.graph, self.graph.path_ids(sid))
        if failing is not None:
            steps.append(failing.step)
        return Path(initial, tuple(steps))

    def _tick(self) -> None:
        now = time.monotonic()
        if self.limits.max_time_s is not None and now - self._start >= self.limits.max_time_s:
            raise _Stop(f"max-time {self.limits.max_time_s:g} s reached before the search finished")
        if self._progress is not None and now - self._last_report >= self._interval:
            self._last_report = now
            self._progress(self.statistics())

    # ------------------------------------------------------- liveness search

    def _holds(self, prop: Property, world: World) -> bool:
        assert prop.expr is not None
        return prop.expr.holds(self.system, world.states, world.now)

    def _lasso(self, prop: Property) -> None:
        found = find_lasso(self.graph, prop.name)
        if found is None:
            return
        ids, start = found
        initial, steps = steps_along(self.system, self.graph, ids)
        path = Path(initial, tuple(steps), start)
        assert prop.expr is not None
        if start is None:
            message = (f"{prop.expr.source!r} never holds on a path that ends with nothing "
                       f"pending ({len(steps)} steps)")
            raise _Found(Violation(prop.name, prop.kind, message, "terminal"), path)
        message = (f"{prop.expr.source!r} never holds on a reachable cycle "
                   f"(steps {start + 1}..{len(steps)} repeat for ever)")
        raise _Found(Violation(prop.name, prop.kind, message, "lasso"), path)

    # ---------------------------------------------------------- random walks

    def _random(self, walks: int, seed: int) -> Outcome:
        rng = random.Random(seed)
        initials = self.system.initial()
        self._initial = len(initials)
        max_depth = self.limits.max_depth or 1000
        for _ in range(walks):
            self._walk(rng, initials, max_depth)
        return self._outcome(UNKNOWN, f"random search is not exhaustive: no violation in {walks} "
                             f"walks of at most {max_depth} steps (seed {seed})")

    def _walk(self, rng: random.Random, initials: list[Transition], max_depth: int) -> None:
        init = rng.choice(initials)
        steps: list[Step] = []
        self._record_walk(init, init.step.choices, steps)
        world = init.world
        seen = {world.digest: 0}
        never = [p for p in self.properties.eventually if not self._holds(p, world)]
        for _ in range(max_depth):
            enabled = self.system.semantics.enabled(world.events)
            if not enabled:
                self._walk_end(never, init, steps, None)
                return
            t = self.system.run(world, rng.choice(enabled), RandomChooser(rng))
            self._transitions += 1
            self._tick()
            steps.append(t.step)
            self._record_walk(t, init.step.choices, steps)
            world = t.world
            self._depth = max(self._depth, len(steps))
            never = [p for p in never if not self._holds(p, world)]
            if world.digest in seen:
                self._walk_end(never, init, steps, seen[world.digest])
            seen[world.digest] = len(steps)

    def _record_walk(self, t: Transition, initial: tuple[int, ...], steps: list[Step]) -> None:
        if t.failure is not None:
            raise _Found(self.properties.check_failure(t.failure), Path(initial, tuple(steps)))
        self.graph.add(t.world.digest, -1)
        violation = self.properties.check_world(self.system, t.world)
        if violation is not None:
            raise _Found(violation, Path(initial, tuple(steps)))
        if self.limits.max_states is not None and len(self.graph) >= self.limits.max_states:
            raise _Stop(f"max-states {self.limits.max_states} reached before the search finished")

    def _walk_end(self, never: list[Property], init: Transition, steps: list[Step],
                  start: int | None) -> None:
        if not never:
            return
        prop = never[0]
        assert prop.expr is not None
        path = Path(init.step.choices, tuple(steps), start)
        if start is None:
            message = f"{prop.expr.source!r} never holds on a path that ends with nothing pending"
            raise _Found(Violation(prop.name, prop.kind, message, "terminal"), path)
        message = f"{prop.expr.source!r} never holds on a reachable cycle"
        raise _Found(Violation(prop.name, prop.kind, message, "lasso"), path)


def bfs(system: System, properties: PropertySet, limits: Limits = Limits(),
        progress: Callable[[SearchStatistics], None] | None = None) -> Outcome:
    """Breadth-first search: the first violation found has a shortest trace."""
    return Search(system, properties, limits, progress=progress).run("bfs")


def dfs(system: System, properties: PropertySet, limits: Limits = Limits(),
        progress: Callable[[SearchStatistics], None] | None = None) -> Outcome:
    """Depth-first order (newest world first)."""
    return Search(system, properties, limits, progress=progress).run("dfs")


def random_walk(system: System, properties: PropertySet, limits: Limits = Limits(), *,
                walks: int = 100, seed: int = 0,
                progress: Callable[[SearchStatistics], None] | None = None) -> Outcome:
    """`walks` seeded random walks of at most `limits.max_depth` (default 1000) steps."""
    return Search(system, properties, limits, progress=progress).run("random", walks=walks,
                                                                     seed=seed)
