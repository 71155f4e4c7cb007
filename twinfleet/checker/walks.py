"""Seeded random walks over a `System`: a simulation mode that finds violations fast
but never proves their absence.

Each walk starts in a random initial world and takes a random action of each
world (`System.actions`) with random answers to its choice points
(`RandomChooser`), checking every safety property and handler failure on the
way, until nothing is pending, `max_depth` steps are taken, or it revisits a
world of its own path: then any `eventually` property that held nowhere on
the walk is violated by the lasso (or by the path that ends).
"""

from __future__ import annotations

import random
from collections.abc import Callable
from typing import final

from twinfleet.checker.choices import RandomChooser
from twinfleet.checker.outcome import Counterexample, Counters, Found, Guard, SearchStatistics
from twinfleet.checker.properties import Property, PropertySet, PropertyViolation
from twinfleet.checker.store import StateStore
from twinfleet.checker.system import System
from twinfleet.checker.transition import Step, Transition
from twinfleet.checker.world import World


@final
class RandomWalks:
    """Random walks for one search (see the module docstring); counts into `counters`
    and records every world it meets in `store` (for the state count)."""

    def __init__(self, system: System, properties: PropertySet, store: StateStore,
                 counters: Counters, guard: Guard,
                 statistics: Callable[[], SearchStatistics]) -> None:
        self.system, self.properties, self.store = system, properties, store
        self.counters, self.guard, self._statistics = counters, guard, statistics

    def run(self, walks: int, seed: int, max_depth: int) -> None:
        """`walks` walks of at most `max_depth` steps; raises `Found` or `Stop`."""
        rng = random.Random(seed)
        initials = self.system.initial()
        self.counters.initial = len(initials)
        for _ in range(walks):
            self._walk(rng, initials, max_depth)

    def _walk(self, rng: random.Random, initials: list[Transition], max_depth: int) -> None:
        init = rng.choice(initials)
        steps: list[Step] = []
        self._record(init, init.step.choices, steps)
        world = init.world
        seen = {world.key: 0}
        never = [p for p in self.properties.eventually if not self._holds(p, world)]
        for _ in range(max_depth):
            actions = self.system.actions(world)
            if not actions:
                self._end(never, init, steps, None)
                return
            t = self.system.step(world, rng.choice(actions), RandomChooser(rng))
            self.counters.transitions += 1
            self.guard.tick(self._statistics)
            steps.append(t.step)
            self._record(t, init.step.choices, steps)
            world = t.world
            self.counters.depth = max(self.counters.depth, len(steps))
            never = [p for p in never if not self._holds(p, world)]
            if world.key in seen:
                self._end(never, init, steps, seen[world.key])
            seen[world.key] = len(steps)

    def _holds(self, prop: Property, world: World) -> bool:
        assert prop.expr is not None
        return prop.expr.holds(self.system, world.states, world.now)

    def _record(self, t: Transition, initial: tuple[int, ...], steps: list[Step]) -> None:
        if t.failure is not None:
            raise Found(self.properties.check_failure(t.failure),
                        Counterexample(initial, tuple(steps)))
        self.store.add(t.world.key, -1)
        violation = self.properties.check_world(self.system, t.world)
        if violation is not None:
            raise Found(violation, Counterexample(initial, tuple(steps)))
        self.guard.count_states(len(self.store))

    def _end(self, never: list[Property], init: Transition, steps: list[Step],
             start: int | None) -> None:
        if not never:
            return
        prop = never[0]
        assert prop.expr is not None
        path = Counterexample(init.step.choices, tuple(steps), start)
        if start is None:
            message = f"{prop.expr.source!r} never holds on a path that ends with nothing pending"
            raise Found(PropertyViolation(prop.name, prop.kind, message, "terminal"), path)
        message = f"{prop.expr.source!r} never holds on a reachable cycle"
        raise Found(PropertyViolation(prop.name, prop.kind, message, "lasso"), path)
