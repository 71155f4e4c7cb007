"""Actions, steps and transitions: what may happen in a world and what it did.

An `Action` is what may happen next in a world (`System.actions`): run one of
its enabled pending events (`RunEvent`, by index into the world's canonically
sorted events), crash a node (`Crash`) or drop a waiting delivery (`Drop`). A `Step` is an action with the
answers its choice points got (`ctx.choose` and the checker's own latency and
fault branches); a trace is a list of steps. A `Variant` is what one run of a
handler did, independent of the world it ran in (new node state, new events,
failure), so the system can cache it; a `Transition` is a step applied to a
world: the next world, and what the step did (which node ran, what it sent,
which node states changed). The helpers compare a node's attributes before
and after a handler (`--debug-state`); `checker.diagnosis` compares two runs.
"""

from __future__ import annotations

import pickle
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple, final

from twinfleet.runtime.contract.context import Log
from twinfleet.runtime.contract.kinds import FailureKind
from twinfleet.runtime.contract.node import PureMemo
from twinfleet.runtime.contract.snapshot import SnapshotError, snapshot

if TYPE_CHECKING:
    from twinfleet.checker.world import Event, World
    from twinfleet.runtime.contract.node import Node


@final
@dataclass(frozen=True, slots=True)
class RunEvent:
    """Run the pending event `index` of a world (into its canonically sorted events)."""

    index: int


@final
@dataclass(frozen=True, slots=True)
class Crash:
    """Crash node `node` at t* and restart it (a fault of `check.faults.crash`)."""

    node: int


@final
@dataclass(frozen=True, slots=True)
class Drop:
    """Drop the pending delivery `index` of a world: KEEP_LAST (Rule 6 of `checker.semantics`)."""

    index: int


Action = RunEvent | Crash | Drop


@final
@dataclass(frozen=True, slots=True)
class Failure:
    """A failed transition: `ctx.fail`, an exception, a deadline miss, nondeterminism..."""

    kind: FailureKind
    node: str
    handler: str
    message: str
    traceback: str = ""

    def __str__(self) -> str:
        return f"{self.kind}: {self.node}.{self.handler}: {self.message}"


@final
class Step(NamedTuple):
    """One transition's identity: its action in the parent world and its choices.

    `action` is None for an initial world (the start handlers' run, not a transition);
    `choices` are the indices every choice point answered, in call order, and
    `options` how many options each had. (A named tuple: one is built per step, and a
    frozen dataclass sets each field through a call.)
    """

    action: Action | None
    choices: tuple[int, ...] = ()
    options: tuple[int, ...] = ()


@final
@dataclass(slots=True)
class Transition:
    """The result of taking one step (or of running the start handlers, for initial worlds).

    Attributes:
        step: the action and its choices.
        world: the next world.
        event: the event that ran (for a crash, a CRASH label whose target is the node).
        failure: why the step failed (then `world` is not to be expanded), or None.
        logs: the handler's `ctx.log` records.
        faults: what the checker's fault branches did, one line each.
        branches: positions in `step.choices` of the checker's own branches (latency,
            drop, duplicate); the others are the handlers' `ctx.choose` answers.
        sent: the events the step added (before FIFO ranks and clamping), each with
            its target, priority and due time; for a crash, the restart's events.
        changed: indices of the nodes whose state the step changed.
        lost: the keys (`Event.key`) of the messages a fault branch of the step lost
            (what weak fairness, `checker.fairness`, must see delivered again).
    """

    step: Step
    world: World
    event: Event
    failure: Failure | None = None
    logs: tuple[Log, ...] = ()
    faults: tuple[str, ...] = ()
    branches: tuple[int, ...] = ()
    sent: tuple[Event, ...] = ()
    changed: tuple[int, ...] = ()
    lost: tuple[bytes, ...] = ()


@final
class Variant(NamedTuple):
    """What one run of a handler (one choice variant) does, independent of the world (a
    named tuple, as `Step` is: one is built per step)."""

    choices: tuple[int, ...]
    options: tuple[int, ...]
    state: bytes
    events: tuple[Event, ...] = ()
    failure: Failure | None = None
    logs: tuple[Log, ...] = ()
    faults: tuple[str, ...] = ()
    # positions in `choices` of the checker's own branches on the effects (latency, drop,
    # duplicate); the others are the handler's ctx.choose answers
    branches: tuple[int, ...] = ()
    lost: tuple[bytes, ...] = ()  # keys of the messages a drop branch lost (Transition.lost)


def fingerprint(node: Node) -> dict[str, bytes]:
    out = {}
    for attr, value in vars(node).items():
        if attr == "state" or isinstance(value, PureMemo):
            continue  # a declared memo of pure functions may fill up: that is not state
        try:
            out[attr] = snapshot(value)
        except (SnapshotError, TypeError, ValueError):
            try:
                out[attr] = pickle.dumps(value)
            except Exception:  # unpicklable configuration: compare by repr
                out[attr] = repr(value).encode()
    return out


def changed_attributes(before: dict[str, bytes], after: dict[str, bytes]) -> list[str]:
    return sorted(k for k in before.keys() | after.keys() if before.get(k) != after.get(k))
