"""One simulation of a `System` under a timing model: the unit of statistical checking.

`Simulator.run(index)` draws its load level first, where the model has levels
(`checker.timing`: every latency of the simulation comes from that level), starts
from an initial world drawn by the start handlers' choices, then repeatedly takes one enabled event, drawn uniformly
among those the rules enable (`System.actions`; KEEP_LAST drops and crash
faults are not drawn: the model has no handler durations to make them
likely), its `ctx.choose` answers and latencies drawn by a `SamplingChooser`,
until nothing is pending, the next event lies beyond the horizon (fleet ms),
or `max_steps` steps were taken. Where the drawn event's node has both a
message and a timer enabled, a model with `messages_first` draws which of the
two kinds runs with that probability (`checker.timing`, ties at one ms).
Every property is watched on the way: each
invariant on its own, handler failures, `within`, queue bounds, deadlock and
quiescence at an end with nothing pending; an `eventually` that held nowhere
by the end is violated within the horizon. With `until_decided` a simulation
also ends ("decided") at its first violation or once every `eventually`
property has held, as a live run of `twinfleet experiment` does (its outcome
is known; what follows would only cost time). A simulation also ends
("settled") once no node state can change any more (`checker.settled`), where
only node states decide the properties: its results are those it would have
had at its horizon. The simulation's generator is
seeded from (seed, index) alone (`simulation_seed`), so simulation `i` is the
same in any process and in any order.
"""

from __future__ import annotations

import hashlib
import random
from bisect import bisect_right
from dataclasses import dataclass
from itertools import accumulate
from typing import final

from twinfleet.checker.diagnosis import CONTRACT_KINDS, breach_line
from twinfleet.checker.outcome import Counterexample
from twinfleet.checker.properties import Property, PropertySet, PropertyViolation
from twinfleet.checker.sampling import SamplingChooser
from twinfleet.checker.settled import settled
from twinfleet.checker.system import System, run_event
from twinfleet.checker.timing import TimingModel
from twinfleet.checker.transition import Step, Transition
from twinfleet.checker.world import Event

SETTLE_AFTER = 64  # steps that changed no node state before asking whether none can


#: (cumulative weights, copula correlation) per (channel, low, n, start-up), as
#: `SamplingChooser` caches them
_Cumulative = dict[tuple[str, int, int, bool], tuple[list[float], float]]


class ContractBreach(RuntimeError):
    """A simulation met a node that breaks the node contract (exit 4, no estimate)."""


def simulation_seed(seed: int, index: int) -> int:
    """The seed of simulation `index` of a run seeded `seed` (independent of workers)."""
    digest = hashlib.blake2b(f"{seed}:{index}".encode(), digest_size=8).digest()
    return int.from_bytes(digest, "big")


@final
@dataclass(frozen=True, slots=True)
class Simulation:
    """What one simulation found.

    Attributes:
        index: its index in the run.
        violated: the properties violated, in the order first seen.
        steps: steps taken; end_ms: the fleet time reached; ended: why it stopped
            ("nothing pending", "horizon", "step limit" or "decided").
        first: the first violation and the path to it (a `Counterexample`), or None;
            `replayable` says whether `twinfleet replay` can confirm it (an `eventually`
            cut by the horizon cannot be).
    """

    index: int
    violated: tuple[str, ...]
    steps: int
    end_ms: int
    ended: str
    first: tuple[PropertyViolation, Counterexample] | None = None
    replayable: bool = False


@final
class Simulator:
    """Runs simulations of `system` (see the module docstring)."""

    def __init__(self, system: System, properties: PropertySet, model: TimingModel, *,
                 seed: int, horizon_ms: int, max_steps: int, until_decided: bool = False,
                 reuse: bool = True) -> None:
        self.system, self.properties, self.model = system, properties, model
        self.seed, self.horizon_ms, self.max_steps = seed, horizon_ms, max_steps
        self.until_decided = until_decided
        # Reuse handler runs across steps and simulations (`Runner.run_kept`); off: run
        # every handler (the same results, slower: for benchmarks and tests).
        self._take = system.draw if reuse else system.step
        self._rest = PropertySet([p for p in properties.all if p.kind != "invariant"],
                                 queue_bounds=properties.queue_bounds,
                                 node_names=properties.node_names,
                                 deadlines=properties.deadlines)
        # Per load level (one for a model without levels): the level's model and the
        # cumulative weights its choosers share.
        self._levels = [(m, _Cumulative()) for m in (
            [model.at_level(k) for k in range(len(model.levels))] or [model])]
        self._level_cum = list(accumulate(lv.weight for lv in model.levels))
        # Without queue bounds or `within`, the other checks of a world find something only
        # where nothing is pending (deadlock, quiescence): most steps skip them.
        self._watch = bool(self._rest.queue_bounds) or bool(properties.within)
        self._first = model.messages_first
        # An expression without `now` is a function of node states alone: a step that
        # changed no state cannot change its value (most steps of a fleet change none).
        self._timeless = not any(p.expr is not None and p.expr.uses_now
                                 for p in (*properties.invariants, *properties.eventually))
        # A run may end early once no node state can change any more (`checker.settled`):
        # only where nothing but node states decides a property (no `within`, queue
        # bound, deadline or `now`), and handler runs are kept.
        self._settles = (reuse and self._timeless and not properties.within
                         and not any(b is not None for b in properties.queue_bounds)
                         and not system.settings.has_deadlines)

    def batch(self, indices: list[int]) -> list[Simulation]:
        """Simulations `indices`, in that order."""
        return [self.run(i) for i in indices]

    def run(self, index: int) -> Simulation:
        """Simulation `index`."""
        rng = random.Random(simulation_seed(self.seed, index))
        system = self.system
        level = self._draw_level(rng)
        init = system.initial_world(chooser=self._chooser(rng, level))
        seen: dict[str, tuple[PropertyViolation, int]] = {}
        self._note(init, 0, seen)
        world, steps = init.world, list[Step]()
        never = {p.name: p for p in self.properties.eventually if not self._holds(p.name, world)}
        ended, quiet = "step limit", 0
        enabled = system.rules.enabled  # the RunEvents of `System.actions`, in its order
        while len(steps) < self.max_steps:
            if self.until_decided and (seen or (self.properties.eventually and not never)):
                ended = "decided"
                break
            if not world.events:
                ended = "nothing pending"
                break
            if world.events[0].due > self.horizon_ms:
                ended = "horizon"
                break
            if quiet >= SETTLE_AFTER:
                if settled(system.runner, world.states, world.events):
                    ended = "settled"
                    break
                quiet = 0
            picks = enabled(world.events)
            pick = rng.choice(picks)
            if self._first is not None and len(picks) > 1:
                pick = self._tie(rng, world.events, picks, pick)
            t = self._take(world, run_event(pick), self._chooser(rng, level))
            steps.append(t.step)
            world = t.world
            moved = bool(t.changed) or not self._timeless
            quiet = 0 if moved or not self._settles else quiet + 1
            if moved or t.failure is not None or self._watch or not world.events:
                self._note(t, len(steps), seen, moved)  # else it has nothing to look at
            for name in [n for n in never if self._holds(n, world)] if moved else ():
                del never[name]
        self._never(never, seen, ended, world.now, len(steps))
        return self._result(index, init, steps, seen, world.now, ended)

    def _never(self, never: dict[str, Property], seen: dict[str, tuple[PropertyViolation, int]],
               ended: str, now: int, k: int) -> None:
        """Record each `eventually` in `never` as violated at the end of the run."""
        if ended == "decided":  # decided by a violation: the others were cut short
            return
        for name, prop in never.items():
            shape = "terminal" if ended == "nothing pending" else "horizon"
            source = prop.expr.source if prop.expr is not None else ""
            when = (f"t={self.horizon_ms} ms (horizon; no node state could change after "
                    f"t={now} ms)" if ended == "settled" else f"t={now} ms ({ended})")
            seen.setdefault(name, (PropertyViolation(
                name, prop.kind, f"{source!r} never held by {when}", shape), k))

    def _tie(self, rng: random.Random, events: tuple[Event, ...], picks: list[int],
             index: int) -> int:
        """The event to run instead of the drawn `events[index]`: when its node has both
        messages and timers among `picks`, one of the kind drawn by `messages_first`."""
        target = events[index].target
        mine = [i for i in picks if events[i].target == target]
        if len(mine) == 1:
            return index
        messages = [i for i in mine if events[i].message]
        if not messages or len(messages) == len(mine):
            return index
        assert self._first is not None
        pool = messages if rng.random() < self._first else [
            i for i in mine if not events[i].message]
        return index if index in pool else rng.choice(pool)

    def _draw_level(self, rng: random.Random) -> int:
        """The load level of one simulation, drawn by the levels' weights (no draw, and so
        the same simulations as before levels existed, for a model without levels)."""
        if not self._level_cum:
            return 0
        u = rng.random() * self._level_cum[-1]
        return min(bisect_right(self._level_cum, u), len(self._levels) - 1)

    def _chooser(self, rng: random.Random, level: int) -> SamplingChooser:
        model, cumulative = self._levels[level]
        return SamplingChooser(rng, model, cumulative)

    def _holds(self, name: str, world: object) -> bool:
        prop = self.properties.eventually_named(name)
        assert prop.expr is not None
        return prop.expr.holds(self.system, world.states, world.now)  # type: ignore[attr-defined]

    def _note(self, t: Transition, k: int, seen: dict[str, tuple[PropertyViolation, int]],
              moved: bool = True) -> None:
        """Record the properties first violated by the transition to step `k` (`moved`:
        whether the invariants can have changed value since the step before)."""
        if t.failure is not None:
            if t.failure.kind in CONTRACT_KINDS:
                raise ContractBreach(breach_line(t.failure.kind, t.failure.node,
                                                 t.failure.handler, t.failure.message))
            violation = self.properties.check_failure(t.failure)
            seen.setdefault(violation.property, (violation, k))
        world, system = t.world, self.system
        for prop in self.properties.invariants if moved else ():
            if prop.name not in seen:
                assert prop.expr is not None
                if not prop.expr.holds(system, world.states, world.now):
                    seen[prop.name] = (PropertyViolation(
                        prop.name, prop.kind,
                        f"invariant {prop.expr.source!r} is false at t={world.now} ms"), k)
        other = self._rest.check_world(system, world) if self._watch or not world.events \
            else None
        if other is not None:
            seen.setdefault(other.property, (other, k))

    def _result(self, index: int, init: Transition, steps: list[Step],
                seen: dict[str, tuple[PropertyViolation, int]], end: int,
                ended: str) -> Simulation:
        if not seen:
            return Simulation(index, (), len(steps), end, ended)
        order = sorted(seen.items(), key=lambda item: item[1][1])
        violation, k = order[0][1]
        path = Counterexample(init.step.choices, tuple(steps[:k]))
        return Simulation(index, tuple(name for name, _ in order), len(steps), end, ended,
                          (violation, path), violation.shape != "horizon")
