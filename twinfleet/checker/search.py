"""State-space search: BFS, DFS, random walks, and the lasso search for liveness.

`Search.run("bfs")` explores breadth-first, so the first violation found has
a shortest trace; "dfs" pops the newest world first (less memory on deep
spaces); both check every safety property on every new world and every
handler failure on every transition, and stop at the first violation. Visited
states live in a `checker.store.StateStore` (64-bit digests, or 128-bit with
`exact_states`); when the scenario has `eventually` properties it also
records every edge, and once the safety search is complete each of them is
checked on that graph by `find_lasso` (no handler is re-run). "random" runs
seeded random walks instead (`checker.walks`) and can only find violations,
never prove their absence. Every search works on the model's API only:
`System.initial`, `System.successors` (every outcome of every action) and,
for walks, `System.actions` and `System.step`.

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

import time
from collections.abc import Callable, Iterable
from functools import partial
from itertools import chain
from typing import TYPE_CHECKING, Any, final

from twinfleet.checker.growth import SAMPLE_MASK
from twinfleet.checker.late_start import Start, start
from twinfleet.checker.outcome import (
    INTERRUPTED_REASON,
    NO_LIMITS,
    Counterexample,
    Found,
    Limits,
    Outcome,
    SearchStatistics,
    Stop,
    peak_rss_mb,
)
from twinfleet.checker.properties import Property, PropertySet
from twinfleet.checker.search_state import FORGET_EVERY, SearchState
from twinfleet.checker.system import System
from twinfleet.checker.transition import Transition
from twinfleet.checker.world import World, earliest_time
from twinfleet.runtime.contract.kinds import Status
from twinfleet.runtime.scenario.property_eval import Overtime, time_limit

if TYPE_CHECKING:
    from twinfleet.checker.reduction import Reduction

__all__ = ["Counterexample", "Limits", "Outcome", "Search", "SearchStatistics", "bfs", "dfs",
           "peak_rss_mb", "random_walk"]

_GRACE_S = 0.25  # after max-time, before a property still running is interrupted


class _Restart(Exception):
    """The send relation a reduced search relies on grew: explore again."""


class _Start(_Restart):
    """The reduction that waited starts: explore again, reduced (`checker.late_start`)."""


@final
class Search(SearchState):
    """One search over a `System` for a `PropertySet` (module docstring); its state,
    statistics and checkpoints are `SearchState`'s, with the same arguments."""

    def run(self, strategy: str = "bfs", *, walks: int = 100, seed: int = 0) -> Outcome:
        """Search with `strategy` ("bfs", "dfs" or "random") until a verdict or a limit."""
        self.guard.restart_clock()
        self._last_checkpoint = self.guard.started
        self._strategy = strategy
        limit = self.limits.max_time_s
        # A backstop for a property that runs past the limit (runtime.scenario.property_eval); the
        # grace lets the search's own check stop cleanly between expansions first.
        with self.guard.sigint_handler(), time_limit(None if limit is None else limit + _GRACE_S):
            try:
                if strategy == "random":
                    return self._random(walks, seed)
                if strategy not in ("bfs", "dfs"):
                    raise ValueError(f"unknown search strategy {strategy!r}")
                self._lifo = strategy == "dfs"
                self._explore_until_stable()
                if self._pruned:
                    return self._outcome(Status.UNKNOWN, f"max-depth {self.limits.max_depth} "
                                         "reached before the search finished")
                for prop in self.properties.eventually:
                    self._lasso(prop)
                return self._outcome(Status.HOLDS, "every property holds")
            except Found as found:
                return self._outcome(Status.VIOLATED, found.violation.property, found.violation,
                                     found.counterexample)
            except Stop as stop:
                return self._stopped(stop.reason, clean=True)
            except KeyboardInterrupt:  # a second Ctrl-C: anywhere, maybe inside the store
                return self._stopped(INTERRUPTED_REASON, clean=False)
            except Overtime as exc:  # inside an expression: the expansion is half done
                return self._stopped(f"max-time {limit:g} s reached while evaluating the "
                                     f"property {exc}", clean=False)

    # -------------------------------------------------------- safety search

    def _explore_until_stable(self) -> None:
        """Explore; with a reduction, start again from scratch whenever the send relation
        it relies on grew during the search (`checker.publications`): at once in a DFS, at
        the end of the level in a BFS, which learns level by level (`Publications.freeze`)."""
        reduction = self.reduction
        if reduction is not None and not self._lifo:
            reduction.freeze()
        while True:
            if reduction is not None:
                reduction.begin()
            try:
                self._explore()
                return
            except _Start:
                self._reset()
            except _Restart:
                assert reduction is not None
                if reduction.aside:  # it did not pay: the rest of the run is unreduced
                    self._aside = reduction.aside
                    self.reduction = reduction = None
                else:
                    reduction.walk_on([w for w, _, _ in self._frontier], len(self.store),
                                      self.limits.max_depth)
                    reduction.restarted()
                self._reset()

    def _explore(self) -> None:
        max_depth = self.limits.max_depth
        if not self._resumed:
            if self._initial is None:
                self._initial = self.system.initial()
            for init in self._initial:
                self.counters.initial += 1
                self._discover(init, -1, 0)
        frontier = self._frontier
        pop = frontier.pop if self._lifo else frontier.popleft
        edges = self.store.edges
        successors = self.system.successors
        reduction = self.reduction
        find = self.store.find
        lifo = self._lifo
        counters = self.counters
        # without checkpoints, a tick is only the guard's (one call less per expansion)
        tick = self._tick if self._checkpoint is not None else partial(self.guard.tick,
                                                                           self.statistics)
        # A BFS: the ids of the worlds the transitions of its level reached so far,
        # by key. Most revisits reach a world found a moment ago from a sibling (interleavings
        # that meet again), and a dict answers them without the store's probe or a call
        # (three robots in lanes: half the transitions, 0.2-0.3 s of 5.5).
        reached: dict[Any, int] | None = None if lifo else {}
        while frontier:
            item = pop()
            world, sid, depth = item
            if not lifo and depth > self._level[0]:
                try:
                    self._next_level(depth, world)
                except _Restart:
                    frontier.appendleft(item)  # the level whole, for `Reduction.walk_on`
                    raise
                reduction = self.reduction  # None once it stepped aside in place
                if reached is not None:
                    reached.clear()  # a level deeper: its worlds are the next level's
            if max_depth is not None and depth >= max_depth:
                self._pruned = True
                continue
            self._expanding = item
            self._expanded_from = counters.transitions
            below = depth + 1
            transitions = (successors(world) if reduction is None
                           else reduction.successors(world, find, None if lifo else self._level[1]))
            children = self._children(transitions, sid, below, reached)
            if edges is not None:
                edges.set(sid, children)
            self._expanding = None
            if lifo and reduction is not None and (reduction.waiting or reduction.stale
                                                   or reduction.steps_aside()):
                self._lifo_turn(reduction)  # a (re)start, unless it stepped aside in place
                reduction = self.reduction
            self._expansions += 1
            if self._expansions >= self._next_forget:
                self._forget()
            tick()
        if reduction is not None and reduction.stale and not reduction.waiting:
            reduction.steps_aside()  # a search that did not pay starts again unreduced
            self._step_aside()

    def _children(self, transitions: Iterable[Transition], sid: int, below: int,
                  reached: dict[Any, int] | None) -> list[int]:
        """The ids of one world's children, each discovered; a BFS answers a revisit within
        its level from `reached` (by key), without the store."""
        counters, discover, children = self.counters, self._discover, []
        if reached is None:
            for t in transitions:
                counters.transitions += 1
                children.append(discover(t, sid, below))
            return children
        for t in transitions:
            counters.transitions += 1
            if t.failure is not None:
                discover(t, sid, below)  # raises Found
            key = t.world.key
            child = reached.get(key)
            if child is None:
                child = reached[key] = discover(t, sid, below)
            children.append(child)
        return children

    def _next_level(self, depth: int, first: World) -> None:
        """A BFS starts expanding the worlds of `depth` (`first` the first of them): every
        world at most that deep is stored. Restart if the level before learned a send, or
        a walk ahead, once the search is large, did (`Reduction.probe`); start again
        unreduced if the reduction does not pay (`Reduction.steps_aside`). A pass that
        reduced no world yet learns in place instead: it expanded every world fully, so
        nothing it did relied on the relation (every search's first level, mostly)."""
        reduction = self.reduction
        if reduction is not None and reduction.waiting:
            self._start(reduction, chain((first,), (w for w, _, _ in self._frontier)))
        elif reduction is not None:
            if reduction.steps_aside():
                self._step_aside()
            else:
                reduction.probe(len(self.store), self.limits.max_depth)
                if reduction.must_restart():
                    raise _Restart
                if reduction.stale:
                    reduction.walk_on([first, *(w for w, _, _ in self._frontier)],
                                      len(self.store), self.limits.max_depth)
                    reduction.learned()
        self._level = (depth, len(self.store) - 1)

    def _start(self, reduction: Reduction, frontier: Iterable[World]) -> None:
        """While the reduction waits (`checker.late_start`): go on, start again reduced, or
        go on unreduced for good."""
        begun = start(reduction, len(self.store), frontier)
        if begun is Start.REDUCE:
            raise _Start
        if begun is Start.ASIDE:
            self._aside, self.reduction = reduction.aside, None

    def _lifo_turn(self, reduction: Reduction) -> None:
        """A DFS after an expansion that left the reduction waiting, its relation stale or
        not paying: `_start`, or `_step_aside`."""
        if reduction.waiting:
            self._start(reduction, (w for w, _, _ in reversed(self._frontier)))
        else:
            self._step_aside()

    def _step_aside(self) -> None:
        """Restart; unless the reduction stepped aside and no world of this pass was
        reduced: then every world so far was expanded fully, in the unreduced search's
        order, so the search goes on unreduced from here (a restart would search them
        again: the two-phase commit's 400-480 worlds, a quarter of its extra time)."""
        reduction = self.reduction
        if reduction is None or reduction.aside is None or reduction.stats.reduced:
            raise _Restart
        self._aside, self.reduction = reduction.aside, None

    def _forget(self) -> None:
        """Let the system drop cached outcomes no world left to expand can use.

        Runs every 512 expansions, or every len(frontier) when that is larger, so
        scanning the frontier costs O(1) per expansion. Not while reducing: a restart
        starts again from time 0 and uses those outcomes again (C1a: 21 % of the reduced
        search's time; the cache stays bounded by its generations).
        """
        self._next_forget = self._expansions + max(FORGET_EVERY, len(self._frontier))
        if self.reduction is not None:
            return
        due = earliest_time(w for w, _, _ in self._frontier)
        if due is not None:
            self.system.forget_before(due)

    def _discover(self, t: Transition, parent: int, depth: int) -> int:
        if t.failure is not None:
            raise Found(self.properties.check_failure(t.failure), self._path_to(parent, t))
        world = t.world
        store = self.store
        sid, new = store.add(world.key, parent, terminal=not world.events)
        if not new:
            return sid
        if parent < 0:
            store.roots[sid] = t.step.choices
        counters = self.counters
        if depth > counters.depth:
            counters.depth = depth
        if store.holds:
            for name, bits in store.holds.items():
                bits.append(self._holds(self.properties.eventually_named(name), world))
        violation = self.properties.check_world(self.system, world)
        if violation is not None:
            raise Found(violation, self._path_to(sid))
        if not sid & SAMPLE_MASK and self._expanding is not None:
            self.growth.observe(self._expanding[0], t)
        frontier = self._frontier
        frontier.append((world, sid, depth))
        if len(frontier) > counters.peak_frontier:
            counters.peak_frontier = len(frontier)
        if self._max_states is not None:
            self.guard.count_states(len(self.store))
        return sid

    def _path_to(self, sid: int, failing: Transition | None = None) -> Counterexample:
        if sid < 0:  # a start handler failed: no steps
            assert failing is not None
            return Counterexample(failing.step.choices, ())
        from twinfleet.checker.paths import steps_along  # here: a check that holds needs none

        initial, steps = steps_along(self.system, self.store, self.store.path_ids(sid))
        if failing is not None:
            steps.append(failing.step)
        return Counterexample(initial, tuple(steps))

    def _tick(self) -> None:
        self.guard.tick(self.statistics)
        if (self._checkpoint is not None
                and time.monotonic() - self._last_checkpoint >= self._checkpoint_every):
            self.save(self._checkpoint)

    # ------------------------------------------------------- liveness search

    def _holds(self, prop: Property, world: World) -> bool:
        assert prop.expr is not None
        return prop.expr.holds(self.system, world.states, world.now)

    def _lasso(self, prop: Property) -> None:
        from twinfleet.checker.paths import lasso_counterexample

        found = lasso_counterexample(self.system, self.store, prop)
        if found is not None:
            raise Found(*found)

    # ---------------------------------------------------------- random walks

    def _random(self, walks: int, seed: int) -> Outcome:
        max_depth = self.limits.max_depth or 1000
        from twinfleet.checker.walks import RandomWalks

        RandomWalks(self.system, self.properties, self.store, self.counters, self.guard,
                    self.statistics).run(walks, seed, max_depth)
        return self._outcome(Status.UNKNOWN, f"random search is not exhaustive: no violation in "
                             f"{walks} walks of at most {max_depth} steps (seed {seed})")


def bfs(system: System, properties: PropertySet, limits: Limits = NO_LIMITS,
        progress: Callable[[SearchStatistics], None] | None = None) -> Outcome:
    """Breadth-first search: the first violation found has a shortest trace."""
    return Search(system, properties, limits, progress=progress).run("bfs")


def dfs(system: System, properties: PropertySet, limits: Limits = NO_LIMITS,
        progress: Callable[[SearchStatistics], None] | None = None) -> Outcome:
    """Depth-first order (newest world first)."""
    return Search(system, properties, limits, progress=progress).run("dfs")


def random_walk(system: System, properties: PropertySet, limits: Limits = NO_LIMITS, *,
                walks: int = 100, seed: int = 0,
                progress: Callable[[SearchStatistics], None] | None = None) -> Outcome:
    """`walks` seeded random walks of at most `limits.max_depth` (default 1000) steps."""
    return Search(system, properties, limits, progress=progress).run("random", walks=walks,
                                                                     seed=seed)
