"""The initial worlds of a `checker.system.System`: node start, then every start handler.

Node start comes first (each node is announced to the `/_liveliness` subscribers
before anything runs, as Zenoh announces a node's token before it publishes),
then the `@on_start` handlers of every node in order, each a run of the
`Runner`; choices made there (`ctx.choose`) give one initial world per
combination. With the contract checks on (`Runner.verify`), the whole start
phase runs twice and must give the same world: a start handler that depends on
another node's hidden state is a contract breach, named here.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Protocol

from twinfleet.checker.choices import ExploringChooser, PrefixChooser
from twinfleet.checker.diagnosis import FIX_HIDDEN
from twinfleet.checker.transition import Failure, Step, Transition
from twinfleet.checker.world import ENVIRONMENT, Event
from twinfleet.runtime.contract.kinds import EventKind, FailureKind

if TYPE_CHECKING:
    from twinfleet.checker.builder import WorldBuilder
    from twinfleet.checker.runner import Runner
    from twinfleet.checker.semantics import Rules
    from twinfleet.checker.topology import Topology
    from twinfleet.runtime.contract.context import Log


class System(Protocol):
    """What the start phase needs of `checker.system.System` (which calls it)."""

    rules: Rules
    runner: Runner
    topology: Topology

    @property
    def nodes(self) -> Sequence[Any]: ...
    @property
    def names(self) -> Sequence[str]: ...

    def initial_world(self, choices: tuple[int, ...] = (), *,
                      chooser: ExploringChooser | None = None) -> Transition: ...


def initial_transitions(system: System) -> list[Transition]:
    """Every initial world of `system` (one per combination of start-handler choices)."""
    result = []
    prefix: tuple[int, ...] | None = ()
    while prefix is not None:
        chooser = PrefixChooser(prefix)
        t = system.initial_world(chooser=chooser)
        if system.runner.verify and t.failure is None:
            t = _recheck(system, t)
        result.append(t)
        prefix = chooser.next_prefix()
    return result


def initial_world(system: System, worlds: WorldBuilder, choices: tuple[int, ...] = (), *,
                  chooser: ExploringChooser | None = None) -> Transition:
    """The initial world reached with the start-handler `choices` (or `chooser`)."""
    chooser = chooser if chooser is not None else PrefixChooser(choices)
    rules, runner = system.rules, system.runner
    states = list(system.topology.initial_states)
    pending: list[Event] = []
    for ev in system.topology.started():  # before the start handlers' events: Zenoh
        rules.add(pending, ev)            # announces a node before it runs anything
    failure: Failure | None = None
    logs: list[Log] = []
    faults: list[str] = []
    branches: list[int] = []
    i = 0
    for i in range(len(system.nodes)):
        v = runner.start(i, states[i], 0, chooser)
        states[i] = v.state
        logs += v.logs
        faults += v.faults
        branches += v.branches
        for ev in v.events:
            rules.add(pending, ev)
        failure = v.failure
        if failure is not None:
            break
    step = Step(None, tuple(chooser.indices), tuple(chooser.options))
    world = worlds.world(0, tuple(states), pending, None)
    label = Event(0, EventKind.START, i, "", ENVIRONMENT, (), 0)
    return Transition(step, world, label, failure, tuple(logs), tuple(faults), tuple(branches))


def _recheck(system: System, t: Transition) -> Transition:
    """`t` again from scratch; a different world is a contract breach naming the nodes."""
    system.runner.forget_loaded()
    again = system.initial_world(t.step.choices)
    if again.world.digest == t.world.digest and again.step == t.step:
        return t
    differ = [name for name, a, b in zip(system.names, t.world.states, again.world.states,
                                         strict=True) if a != b] or list(system.names)
    failure = Failure(FailureKind.NONDETERMINISM, ", ".join(differ), "on_start",
                      "running every node's start handlers twice gave different initial "
                      f"worlds (a start handler depends on another's hidden state); fix: "
                      f"{FIX_HIDDEN}")
    return Transition(t.step, t.world, t.event, failure, t.logs, t.faults)
