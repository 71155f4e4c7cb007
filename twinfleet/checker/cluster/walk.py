"""A distributed search's counterexamples and graph, put together in the coordinator.

The workers keep, per visited key, the key of the world it was first reached from
(`ShardCore.lineage`); a counterexample is the chain of those keys from the violating
world back to an initial one, run forward again from the initial world's choices
(`walk`). The node code is deterministic by the contract, so each step is found among
the world's successors by its key; one that is not is a contract breach (`NOT_AGAIN`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

from twinfleet.checker.cluster.level import ROOT, Graph
from twinfleet.checker.diagnosis import FIX_HIDDEN, ContractBreachError, breach_line
from twinfleet.checker.outcome import Counterexample
from twinfleet.checker.paths import lasso_counterexample
from twinfleet.checker.properties import PropertySet, PropertyViolation
from twinfleet.checker.store import StateStore
from twinfleet.checker.system import System
from twinfleet.checker.world import World
from twinfleet.runtime.contract.kinds import FailureKind

NOT_AGAIN = breach_line(
    FailureKind.NONDETERMINISM, "", "(unknown)", "a path the search recorded does not run "
    "again from its initial world: some handler depends on something outside self.state; "
    f"rerun with --check-determinism to name it; fix: {FIX_HIDDEN}")


def walk(system: System, roots: Mapping[int, tuple[int, ...]],
         lineage: Callable[[int], list[int]], key: int) -> tuple[Counterexample, World]:
    """The steps from an initial world to the world with `key`, along recorded parents
    (`lineage(k)`: k's parent and maybe further ancestors, ending with ROOT or a key to ask
    about next), and the world reached."""
    keys = [key]
    while keys[-1] != ROOT:
        keys += lineage(keys[-1])
    keys.pop()
    keys.reverse()
    initial = roots[keys[0]]
    world = system.initial_world(initial).world
    steps = []
    for nxt in keys[1:]:
        step = next((t for t in system.successors(world)
                     if t.failure is None and t.world.key == nxt), None)
        if step is None:
            raise ContractBreachError(NOT_AGAIN)
        steps.append(step.step)
        world = step.world
    return Counterexample(initial, tuple(steps)), world


def failing_step(system: System, properties: PropertySet, path: Counterexample,
                 world: World) -> tuple[PropertyViolation, Counterexample]:
    """A handler failed on a step from `world` (reached by `path`): the first failing step
    from there, as a violation and its counterexample."""
    for t in system.successors(world):
        if t.failure is not None:
            return (properties.check_failure(t.failure),
                    Counterexample(path.initial, (*path.steps, t.step)))
    raise ContractBreachError(NOT_AGAIN)


def gathered(parts: list[Graph], visited: list[bytes], roots: Mapping[int, tuple[int, ...]],
             properties: PropertySet) -> StateStore:
    """The whole graph as a one-process search records it (ids, first-discovery parents,
    roots, terminal worlds, the properties' bits and the successor ids), from what every
    process saw of it and every partition's visited keys."""
    graph = Graph()
    for part in parts:
        graph.extend(part)
    store = graph.store(visited, dict(roots), tuple(p.name for p in properties.eventually))
    for key, choices in roots.items():
        store.roots[store.find(key)] = choices
    return store


def first_lasso(system: System, store: StateStore, properties: PropertySet
                ) -> tuple[PropertyViolation, Counterexample] | None:
    """The first `eventually` property a lasso of the gathered graph violates, with its
    counterexample (`checker.paths`), or None: every one holds."""
    for prop in properties.eventually:
        found = lasso_counterexample(system, store, prop)
        if found is not None:
            return found
    return None
