"""State-space search: BFS, DFS, random walks, and the lasso search for liveness.

`Search.run("bfs")` explores breadth-first, so the first violation found has
a shortest trace; "dfs" pops the newest world first (less memory on deep
spaces); both check every safety property on every new world and every
handler failure on every transition, and stop at the first violation. Visited
states live in a `checker.store.StateStore` (64-bit digests, or 128-bit with
`exact_states`); when the scenario has `eventually` properties it also
records every edge, and once the safety search is complete each of them is
checked on that graph by `find_lasso` (no handler is re-run). "random" runs
seeded random walks instead and can only find violations, never prove their
absence.

A search stops cleanly between two expansions on Ctrl-C (the first SIGINT
sets a flag; a second one interrupts at once), on `max_time_s` and on
`max_states` (then the world being expanded is put back), so it can always be
saved: with `checkpoint=PATH` it writes `checker.checkpoint` files every
`checkpoint_every_s` seconds and when it stops early, and `Search.restore`
continues one to the same result as an uninterrupted run.

Counters (`SearchStatistics`): `states` are distinct worlds and `transitions`
every handler run (one per choice variant, revisits included).
"""

from __future__ import annotations

import random
import resource
import signal
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, final

from twinfleet.checker import checkpoint
from twinfleet.checker.choices import RandomChooser
from twinfleet.checker.graph import find_lasso, steps_along
from twinfleet.checker.properties import Property, PropertySet, Violation
from twinfleet.checker.store import StateStore
from twinfleet.checker.system import Step, System, Transition
from twinfleet.checker.world import World

HOLDS, VIOLATED, UNKNOWN = "holds", "violated", "unknown"
INTERRUPTED = "interrupted (Ctrl-C)"
_FORGET_EVERY = 512  # expansions between two `System.forget_before` calls (at least)


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
    checkpoint: str | None = None  # the checkpoint file written when the search stopped early


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
        checkpoint: file to save the search to (periodically and when it stops early).
        checkpoint_every_s: seconds between periodic checkpoints.
        checkpoint_meta: what the checkpoint must record to be resumed (scenario, options).
        handle_sigint: stop cleanly on the first Ctrl-C (main thread only).
    """

    def __init__(self, system: System, properties: PropertySet, limits: Limits = Limits(), *,
                 progress: Callable[[SearchStatistics], None] | None = None,
                 progress_interval: float = 1.0, checkpoint: str | None = None,
                 checkpoint_every_s: float = 300.0,
                 checkpoint_meta: Mapping[str, Any] | None = None,
                 handle_sigint: bool = True) -> None:
        self.system = system
        self.properties = properties
        self.limits = limits
        self._progress = progress
        self._interval = progress_interval
        live = tuple(p.name for p in properties.eventually)
        self.store = StateStore(exact=system.exact_states, record_edges=bool(live), flags=live)
        self._frontier: deque[tuple[World, int, int]] = deque()
        self._transitions = 0
        self._initial = 0
        self._depth = 0
        self._peak_frontier = 0
        self._expansions = 0
        self._next_forget = _FORGET_EVERY
        self._pruned = False
        self._resumed = False
        self._elapsed_before = 0.0
        self._expanding: tuple[World, int, int] | None = None
        self._partial = 0
        self._sigint = False
        self._handle_sigint = handle_sigint
        self._checkpoint = checkpoint
        self._checkpoint_every = checkpoint_every_s
        self._checkpoint_meta = dict(checkpoint_meta or {})
        self._lifo = False
        self._strategy = "bfs"
        self._start = time.monotonic()
        self._last_report = self._last_checkpoint = self._start

    def statistics(self) -> SearchStatistics:
        """The counters so far."""
        store = self.store
        return SearchStatistics(
            len(store), self._transitions, self._initial, self._depth, len(self._frontier),
            self._elapsed_before + time.monotonic() - self._start, peak_rss_mb(), store.nbytes(),
            store.digest_bits, store.collision_probability(0 if store.exact else self.system.hashed),
            self._peak_frontier)

    def run(self, strategy: str = "bfs", *, walks: int = 100, seed: int = 0) -> Outcome:
        """Search with `strategy` ("bfs", "dfs" or "random") until a verdict or a limit."""
        self._start = self._last_report = self._last_checkpoint = time.monotonic()
        self._strategy = strategy
        with self._sigint_handler():
            try:
                if strategy == "random":
                    return self._random(walks, seed)
                if strategy not in ("bfs", "dfs"):
                    raise ValueError(f"unknown search strategy {strategy!r}")
                self._lifo = strategy == "dfs"
                self._explore()
                if self._pruned:
                    return self._outcome(UNKNOWN, f"max-depth {self.limits.max_depth} reached "
                                         "before the search finished")
                for prop in self.properties.eventually:
                    self._lasso(prop)
                return self._outcome(HOLDS, "every property holds")
            except _Found as found:
                return self._outcome(VIOLATED, found.violation.property, found.violation,
                                     found.path)
            except _Stop as stop:
                return self._stopped(stop.reason, clean=True)
            except KeyboardInterrupt:  # a second Ctrl-C: anywhere, maybe inside the store
                return self._stopped(INTERRUPTED, clean=False)

    def _stopped(self, reason: str, *, clean: bool) -> Outcome:
        """An early stop: put back a half-expanded world, then save a checkpoint if asked.

        `_Stop` is only raised where the store is consistent (between expansions,
        or right after a state was added), so the world being expanded can be put
        back and expanded again on resume: it re-finds the successors already
        added as known states, in the same order.
        """
        saved = None
        if clean and self._expanding is not None:
            self._transitions -= self._partial
            if self._lifo:
                self._frontier.append(self._expanding)
            else:
                self._frontier.appendleft(self._expanding)
            self._expanding = None
            self._partial = 0
        if clean and self._checkpoint is not None and self._strategy != "random":
            self.save(self._checkpoint)
            saved = self._checkpoint
        outcome = self._outcome(UNKNOWN, reason)
        outcome.checkpoint = saved
        return outcome

    def _outcome(self, status: str, reason: str, violation: Violation | None = None,
                 path: Path | None = None) -> Outcome:
        return Outcome(status, reason, self.statistics(), violation, path)

    @contextmanager
    def _sigint_handler(self) -> Iterator[None]:
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

    # ------------------------------------------------------ checkpoints

    def save(self, path: str) -> None:
        """Write the search (store, frontier, counters) to `path` atomically."""
        counters = {"transitions": self._transitions, "initial": self._initial,
                    "depth": self._depth, "pruned": self._pruned,
                    "peak_frontier": self._peak_frontier,
                    "elapsed": self._elapsed_before + time.monotonic() - self._start,
                    "hashed": self.system.hashed,
                    "strategy": "dfs" if self._lifo else "bfs"}
        checkpoint.save(path, self._checkpoint_meta, self.store, list(self._frontier), counters)
        self._last_checkpoint = time.monotonic()

    def restore(self, data: Mapping[str, Any]) -> None:
        """Continue from a loaded checkpoint (`checker.checkpoint.load`)."""
        self.store = data["store"]
        self._frontier = deque(data["frontier"])
        c = data["counters"]
        self._transitions, self._initial, self._depth = c["transitions"], c["initial"], c["depth"]
        self._pruned, self._peak_frontier = c["pruned"], c["peak_frontier"]
        self._elapsed_before = c["elapsed"]
        self.system.hashed += c["hashed"]
        self._resumed = True

    # -------------------------------------------------------- safety search

    def _explore(self) -> None:
        max_depth = self.limits.max_depth
        if not self._resumed:
            for init in self.system.initial():
                self._initial += 1
                self._discover(init, -1, 0)
        frontier = self._frontier
        pop = frontier.pop if self._lifo else frontier.popleft
        edges = self.store.edges
        successors = self.system.successors
        discover = self._discover
        while frontier:
            item = pop()
            world, sid, depth = item
            if max_depth is not None and depth >= max_depth:
                self._pruned = True
                continue
            self._expanding = item
            children = []
            for t in successors(world):
                self._transitions += 1
                self._partial += 1
                children.append(discover(t, sid, depth + 1))
            if edges is not None:
                edges.set(sid, children)
            self._expanding = None
            self._partial = 0
            self._expansions += 1
            if self._expansions >= self._next_forget:
                self._forget()
            self._tick()

    def _forget(self) -> None:
        """Let the system drop cached outcomes no world left to expand can use.

        Runs every 512 expansions, or every len(frontier) when that is larger, so
        scanning the frontier costs O(1) per expansion.
        """
        self._next_forget = self._expansions + max(_FORGET_EVERY, len(self._frontier))
        times = [w.events[0].due for w, _, _ in self._frontier if w.events]
        if times:
            self.system.forget_before(min(times))

    def _discover(self, t: Transition, parent: int, depth: int) -> int:
        if t.failure is not None:
            raise _Found(self.properties.check_failure(t.failure), self._path_to(parent, t))
        world = t.world
        sid, new = self.store.add(world.key, parent, terminal=not world.events)
        if not new:
            return sid
        if parent < 0:
            self.store.roots[sid] = t.step.choices
        if depth > self._depth:
            self._depth = depth
        for name, bits in self.store.holds.items():
            bits.append(self._holds(self.properties.eventually_named(name), world))
        violation = self.properties.check_world(self.system, world)
        if violation is not None:
            raise _Found(violation, self._path_to(sid))
        self._frontier.append((world, sid, depth))
        if len(self._frontier) > self._peak_frontier:
            self._peak_frontier = len(self._frontier)
        if self.limits.max_states is not None and len(self.store) >= self.limits.max_states:
            raise _Stop(f"max-states {self.limits.max_states} reached before the search finished")
        return sid

    def _path_to(self, sid: int, failing: Transition | None = None) -> Path:
        if sid < 0:  # a start handler failed: no steps
            assert failing is not None
            return Path(failing.step.choices, ())
        initial, steps = steps_along(self.system, self.store, self.store.path_ids(sid))
        if failing is not None:
            steps.append(failing.step)
        return Path(initial, tuple(steps))

    def _tick(self) -> None:
        now = time.monotonic()
        if self._sigint:
            raise _Stop(INTERRUPTED)
        if self.limits.max_time_s is not None and now - self._start >= self.limits.max_time_s:
            raise _Stop(f"max-time {self.limits.max_time_s:g} s reached before the search finished")
        if self._progress is not None and now - self._last_report >= self._interval:
            self._last_report = now
            try:
                self._progress(self.statistics())
            except KeyboardInterrupt:
                raise _Stop(INTERRUPTED) from None
        if self._checkpoint is not None and now - self._last_checkpoint >= self._checkpoint_every:
            self.save(self._checkpoint)

    # ------------------------------------------------------- liveness search

    def _holds(self, prop: Property, world: World) -> bool:
        assert prop.expr is not None
        return prop.expr.holds(self.system, world.states, world.now)

    def _lasso(self, prop: Property) -> None:
        found = find_lasso(self.store, prop.name)
        if found is None:
            return
        ids, start = found
        initial, steps = steps_along(self.system, self.store, ids)
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
        seen = {world.key: 0}
        never = [p for p in self.properties.eventually if not self._holds(p, world)]
        for _ in range(max_depth):
            actions = self.system.actions(world)
            if not actions:
                self._walk_end(never, init, steps, None)
                return
            t = self.system.take(world, rng.choice(actions), RandomChooser(rng))
            self._transitions += 1
            self._tick()
            steps.append(t.step)
            self._record_walk(t, init.step.choices, steps)
            world = t.world
            self._depth = max(self._depth, len(steps))
            never = [p for p in never if not self._holds(p, world)]
            if world.key in seen:
                self._walk_end(never, init, steps, seen[world.key])
            seen[world.key] = len(steps)

    def _record_walk(self, t: Transition, initial: tuple[int, ...], steps: list[Step]) -> None:
        if t.failure is not None:
            raise _Found(self.properties.check_failure(t.failure), Path(initial, tuple(steps)))
        self.store.add(t.world.key, -1)
        violation = self.properties.check_world(self.system, t.world)
        if violation is not None:
            raise _Found(violation, Path(initial, tuple(steps)))
        if self.limits.max_states is not None and len(self.store) >= self.limits.max_states:
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
