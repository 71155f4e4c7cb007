"""What a transition is and what it did: steps, outcomes, failures, and their comparison.

A `Step` identifies a transition within its parent world (event index and
`ctx.choose` answers); a `Variant` is what one run of a handler did,
independent of the world it ran in (new node state, new events, failure), so
the system can cache it; a `Transition` is a step applied to a world. The
helpers compare two runs of the same step (`--check-determinism`) and a
node's attributes before and after a handler (`--debug-state`).
"""

from __future__ import annotations

import pickle
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final, final

from twinfleet.runtime.context import Log
from twinfleet.runtime.snapshot import SnapshotError, snapshot

if TYPE_CHECKING:
    from twinfleet.checker.world import Event, World
    from twinfleet.runtime.node import Node

FAILURE: Final = "handler failure"
DEBUG_STATE: Final = "state outside self.state"
DEADLINE: Final = "deadline miss"
NONDETERMINISM: Final = "nondeterminism"


@final
@dataclass(frozen=True, slots=True)
class Failure:
    """A failed transition: `ctx.fail`, an exception, a deadline miss, nondeterminism..."""

    kind: str  # FAILURE, DEBUG_STATE, DEADLINE or NONDETERMINISM
    node: str
    handler: str
    message: str
    traceback: str = ""

    def __str__(self) -> str:
        return f"{self.kind}: {self.node}.{self.handler}: {self.message}"


@final
@dataclass(frozen=True, slots=True)
class Step:
    """One transition's identity: the event index in the parent world and its choices.

    For a crash fault (`crash=True`) `event` is the index of the crashing node.
    """

    event: int
    choices: tuple[int, ...] = ()
    options: tuple[int, ...] = ()
    crash: bool = False


@final
@dataclass(slots=True)
class Transition:
    """The result of running one event variant (or the start handlers, for initial worlds)."""

    step: Step
    world: World
    event: Event
    failure: Failure | None = None
    logs: tuple[Log, ...] = ()
    faults: tuple[str, ...] = ()
    branches: tuple[int, ...] = ()  # positions in step.choices of the checker's own branches


@final
@dataclass(frozen=True, slots=True)
class Variant:
    """What one run of a handler (one choice variant) does, independent of the world."""

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


CAUSES = (". Likely causes: the handler reads the wall clock or `time`, uses `random`, "
          "iterates a set of strings (order depends on PYTHONHASHSEED), or keeps state outside "
          "self.state (rerun with --debug-state)")


def difference(a: Variant, b: Variant) -> str | None:
    """What differs between two runs of the same handler variant, or None."""
    if (a.choices, a.options) != (b.choices, b.options):
        return (f"choices {list(a.choices)} of {list(a.options)} then {list(b.choices)} of "
                f"{list(b.options)}")
    fa = None if a.failure is None else (a.failure.kind, a.failure.message)
    fb = None if b.failure is None else (b.failure.kind, b.failure.message)
    if fa != fb:
        return f"outcome {fa or 'ok'} then {fb or 'ok'}"
    if a.state != b.state:
        return "the new node state differs"
    ea = [(e.sk, e.deadline) for e in a.events]
    eb = [(e.sk, e.deadline) for e in b.events]
    if ea != eb:
        return (f"effects differ: {[(e.kind, e.method, e.args) for e in a.events]} then "
                f"{[(e.kind, e.method, e.args) for e in b.events]}")
    if a.logs != b.logs:
        return "logs differ"
    return None


def fingerprint(node: Node) -> dict[str, bytes]:
    out = {}
    for attr, value in vars(node).items():
        if attr == "state" or getattr(value, "pure_memo", False):
            continue  # a declared memo of a pure function may fill up: that is not state
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
