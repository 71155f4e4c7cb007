"""The follower's only coupling to the checker: build a system, list its steps, take one.

Everything here uses `checker.system.System`'s current API (`initial`,
`successors`, `states_of`, `World.events`); when that API changes, only this
module has to follow it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from twinfleet.checker.driver import load
from twinfleet.checker.system import System


@dataclass(frozen=True)
class Step:
    """One enabled step of our system: node `node` runs `handler` on an event of `kind`.

    `args` are the handler's arguments (the message, or the args of `ctx.after`);
    `choices` the `ctx.choose` answers of this variant; `outcome` is opaque.
    """

    node: str
    handler: str
    kind: str
    due: int
    args: tuple[Any, ...]
    choices: tuple[int, ...]
    outcome: Any


@dataclass(frozen=True)
class Pending:
    """A pending event as the follower compares it: target node, due time, handler, args."""

    node: str
    due: int
    handler: str
    args: tuple[Any, ...]


def build(scenario: str | Path) -> tuple[System, Any]:
    """The checker's system for a scenario file, and its (single) initial world."""
    system = System(load(Path(scenario)))
    (first,) = system.initial()
    return system, first.world


def enabled_steps(system: System, world: Any) -> list[Step]:
    """Every step enabled in `world`: each enabled event times each choice variant."""
    names = system.names
    return [Step(names[t.event.target], t.event.method, t.event.kind, t.event.due, t.event.args,
                 t.step.choices, t) for t in system.successors(world)]


def take(step: Step) -> Any:
    """The world after `step` (its outcome was computed when it was listed)."""
    return step.outcome.world


def node_states(system: System, world: Any) -> dict[str, Any]:
    """Every node's decoded state object, by node name."""
    return system.states_of(world)


def pending(system: System, world: Any) -> list[Pending]:
    """Every pending event of `world`."""
    return [Pending(system.names[e.target], e.due, e.method, e.args) for e in world.events]
