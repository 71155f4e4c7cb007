"""Paths and cycles on the visited-state store (`checker.store.StateStore`).

Steps are not stored: `steps_along` turns a path of state ids back into steps
by re-running the successors of each world on it and taking the one whose key
the store maps to the next id.

`find_lasso` is the liveness check on the recorded graph: a depth-first search
restricted to states where the property's expression is false, colouring
states on the stack grey, so a back edge closes a reachable cycle on which the
expression never holds (a lasso) and a state with nothing pending ends a
finite counterexample; `lasso_counterexample` turns what it finds into the
violation and the `Counterexample` a search reports. Under weak fairness it asks
`checker.fairness` instead, which needs the worlds of some states again
(`world_finder`).
"""

from __future__ import annotations

from collections.abc import Callable

from twinfleet.checker.diagnosis import FIX_HIDDEN, ContractBreachError, breach_line
from twinfleet.checker.fairness import fair_violation
from twinfleet.checker.outcome import Counterexample
from twinfleet.checker.properties import Property, PropertyViolation
from twinfleet.checker.store import StateStore
from twinfleet.checker.system import System
from twinfleet.checker.transition import Step, Transition
from twinfleet.checker.world import World
from twinfleet.runtime.contract.kinds import FailureKind
from twinfleet.runtime.scenario.config import Fairness

_GREY, _BLACK = 1, 2


def steps_along(system: System, store: StateStore, ids: list[int]) -> tuple[tuple[int, ...],
                                                                            list[Step]]:
    """The initial choices and steps that follow the path of state ids `ids`."""
    initial = store.roots[ids[0]]
    world = system.initial_world(initial).world
    steps = []
    for nxt in ids[1:]:
        t = _successor_to(system, store, world, nxt)
        steps.append(t.step)
        world = t.world
    return initial, steps


def world_finder(system: System, store: StateStore) -> Callable[[int], World]:
    """A function giving the world of a state id, rebuilt along its parents from its
    initial world; it keeps every world it rebuilt, so rebuilding many worlds re-runs
    each step of their paths once (their paths share the parents' tree)."""
    known: dict[int, World] = {}

    def world_of(sid: int) -> World:
        ids = store.path_ids(sid)
        k = len(ids)
        while k and ids[k - 1] not in known:
            k -= 1
        if k:
            world = known[ids[k - 1]]
        else:
            world = known[ids[0]] = system.initial_world(store.roots[ids[0]]).world
            k = 1
        for nxt in ids[k:]:
            world = known[nxt] = _successor_to(system, store, world, nxt).world
        return world

    return world_of


def _successor_to(system: System, store: StateStore, world: World, sid: int) -> Transition:
    for t in system.successors(world):
        if t.failure is None and store.find(t.world.key) == sid:
            return t
    raise ContractBreachError(breach_line(
        FailureKind.NONDETERMINISM, "", "(unknown)", "a path the search recorded does not "
        "run again from its initial world: some handler depends on something outside "
        f"self.state that the checks of single runs did not catch; rerun with "
        f"--check-determinism (every transition verified) to name it; fix: {FIX_HIDDEN}"))


def lasso_counterexample(system: System, store: StateStore, prop: Property
                         ) -> tuple[PropertyViolation, Counterexample] | None:
    """The violation of `eventually` property `prop` on the recorded graph, and the path
    that shows it (a lasso, or a path to a world with nothing pending); None if it holds."""
    weak = prop.fairness is Fairness.WEAK
    path = _fair_path(system, store, prop.name) if weak else _any_path(system, store, prop.name)
    if path is None:
        return None
    start, n = path.cycle_start, len(path.steps)
    assert prop.expr is not None
    if start is None:
        message = (f"{prop.expr.source!r} never holds on a path that ends with nothing "
                   f"pending ({n} steps)")
        return PropertyViolation(prop.name, prop.kind, message, "terminal"), path
    assumed = ", every message dropped on it also handled (weak fairness)" if weak else ""
    message = (f"{prop.expr.source!r} never holds on a reachable cycle "
               f"(steps {start + 1}..{n} repeat for ever{assumed})")
    return PropertyViolation(prop.name, prop.kind, message, "lasso"), path


def _any_path(system: System, store: StateStore, prop: str) -> Counterexample | None:
    found = find_lasso(store, prop)
    if found is None:
        return None
    ids, start = found
    initial, steps = steps_along(system, store, ids)
    return Counterexample(initial, tuple(steps), start)


def _fair_path(system: System, store: StateStore, prop: str) -> Counterexample | None:
    fair = fair_violation(system, store, prop, world_finder(system, store))
    if fair is None:
        return None
    initial, steps = steps_along(system, store, fair.stem)
    return Counterexample(initial, (*steps, *fair.cycle), len(steps) if fair.cycle else None)


def find_lasso(store: StateStore, prop: str) -> tuple[list[int], int | None] | None:
    """A path of ids on which `prop` never holds, ending in a cycle or a terminal state.

    Returns (ids, cycle_start) where `ids[-1] == ids[cycle_start]` for a lasso and
    cycle_start is None for a path ending in a terminal state; None if there is none.
    """
    edges = store.edges
    assert edges is not None, "find_lasso needs a store recorded with edges"
    holds, terminal, targets = store.holds[prop], store.terminal, edges.targets
    colour = bytearray(len(store))
    for root in store.roots:
        if holds[root] or colour[root]:
            continue
        colour[root] = _GREY
        if terminal[root]:
            return [root], None
        stack = [root]
        cursor = [edges.out(root)]
        pos = [0]
        while stack:
            out = cursor[-1]
            k = pos[-1]
            if k == len(out):
                colour[stack.pop()] = _BLACK
                cursor.pop()
                pos.pop()
                continue
            pos[-1] = k + 1
            w = targets[out[k]]
            if holds[w] or colour[w] == _BLACK:
                continue
            if colour[w] == _GREY:
                return [*stack, w], stack.index(w)
            colour[w] = _GREY
            stack.append(w)
            cursor.append(edges.out(w))
            pos.append(0)
            if terminal[w]:
                return list(stack), None
    return None
