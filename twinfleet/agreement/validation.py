"""What `twinfleet validate` reports: why a live step is unexplained, and the verdict.

The reason constants name the kinds of difference (`agreement.validate`'s
docstring says when each applies); `Unexplained` is one live event the
checker cannot take, with what the checker expected instead; `Explainer`
works out which reason applies to a live event that no enabled pending event
matches; `Validation` is the whole result, as text or JSON.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any, final

from twinfleet.agreement.events import LiveEvent, Signatures, live_signature
from twinfleet.checker.system import System
from twinfleet.checker.world import Event, World
from twinfleet.runtime.contract.kinds import (
    EXIT_FAILED,
    EXIT_INCONCLUSIVE,
    EXIT_OK,
    EventKind,
)
from twinfleet.runtime.core.eventlog import summarise

START = "startup"
NO_EVENT = "model drift: no such pending event"
PAYLOAD = "model drift: different message"
CHOICES = "model drift: ctx.choose differs"
STATE = "model drift: node state differs"
ERROR = "model drift: handler failure differs"
ORDER = "order: an earlier message of the same stream is pending"
TIMING = "timing outside the model"
OUTSIDE = "outside the model"


@final
@dataclass(frozen=True)
class Unexplained:
    """The first step of a live run that the checker cannot explain.

    Attributes:
        step: the event's 1-based position among the log's events after the starts
            (0: a start event, or the start as a whole).
        event: the live event.
        reason: one of the reason constants of this module.
        expected: what the checker has or does at this point.
        seen: what the live node did.
        notes: other candidates considered at this point and why they failed.
    """

    step: int
    event: LiveEvent | None
    reason: str
    expected: str
    seen: str
    notes: tuple[str, ...] = ()

    def describe(self) -> str:
        """Several lines for a terminal."""
        what = f"{self.event.label()} [{self.event.where()}]" if self.event else "the start"
        lines = [f"step {self.step}: {what}: {self.reason}",
                 f"  expected: {self.expected}", f"  seen:     {self.seen}"]
        lines += [f"  also: {note}" for note in self.notes]
        return "\n".join(lines)


@final
@dataclass
class Validation:
    """What `validate` found."""

    events_path: str
    scenario: str
    semantics: str
    timing: str
    events: int
    explained: int
    failure: Unexplained | None = None
    ahead_steps: int = 0
    max_ahead_ms: int = 0
    max_ahead_at: str = ""
    violations: list[tuple[int, str, str]] = field(default_factory=list)
    backtracks: int = 0
    elapsed_s: float = 0.0

    @property
    def ok(self) -> bool:
        """True when every live event is explained."""
        return self.failure is None

    def exit_code(self, strict: Validation | None = None) -> int:
        """0 a path of the exact model, 1 a step unexplained, 3 a path only if timing is
        ignored (`strict`: the same run judged by the exact timing rules, when this one
        was judged by a looser rule)."""
        if not self.ok:
            return EXIT_FAILED
        return EXIT_OK if strict is None or strict.ok else EXIT_INCONCLUSIVE

    def verdict(self, strict: Validation | None = None) -> str:
        """The first line of the report: the verdict, and any property broken on the path
        (before everything else, since a violation on a path the exact model cannot take
        is no counterexample the checker missed)."""
        if not self.ok:
            return (f"NOT EXPLAINED: {self.explained} of {self.events} events explained; "
                    "first unexplained step:")
        broken = ", ".join(f"{prop} at step {step}" for step, prop, _ in self.violations)
        if strict is None or strict.ok:
            return ("VALID: the live run is a path of the checker's exact model: all "
                    f"{self.events} events explained"
                    + (f"; property {broken} violated on it" if broken else ""))
        gave_up = strict.failure is not None and any(
            n.startswith("the search gave up") for n in strict.failure.notes)
        why = ("no path under the exact timing rules was found within the search's budget"
               if gave_up else "the exact model cannot take it")
        return ((f"OUTSIDE THE MODEL: property {broken} violated on a path only if timing is "
                 f"ignored ({self.timing}); {why}") if broken else
                (f"OUTSIDE THE MODEL: the live run is a path only if timing is ignored "
                 f"({self.timing}): all {self.events} events explained; {why}"))

    def summary(self, strict: Validation | None = None) -> str:
        """A human-readable report, the verdict first (`strict`: as for `verdict`)."""
        head = (f"twinfleet validate {self.events_path} {self.scenario} "
                f"(semantics {self.semantics}, timing {self.timing})")
        lines = [self.verdict(strict), head]
        if self.failure is not None:
            lines.append(self.failure.describe())
        if self.max_ahead_ms:
            lines.append(f"timing: {self.ahead_steps} steps ran ahead of the model's clock t*, "
                         f"by up to {self.max_ahead_ms} ms ({self.max_ahead_at}); this path "
                         f"fits --tolerance-ms {self.max_ahead_ms}")
        else:
            lines.append("timing: every explained step was due at the model's t*")
        for step, prop, message in self.violations:
            lines.append(f"property {prop} violated on this path at step {step}: {message}")
        if strict is not None:
            lines.append(strict_line(strict))
        lines.append(f"time {self.elapsed_s:.2f} s, {self.backtracks} backtracks")
        return "\n".join(lines)

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready record."""
        f = self.failure
        return {"events_path": self.events_path, "scenario": self.scenario,
                "semantics": self.semantics, "timing": self.timing, "ok": self.ok,
                "events": self.events, "explained": self.explained,
                "failure": None if f is None else {
                    "step": f.step, "reason": f.reason, "expected": f.expected, "seen": f.seen,
                    "notes": list(f.notes),
                    "event": None if f.event is None else {
                        "node": f.event.node, "index": f.event.index, "t": f.event.t,
                        "line": f.event.line, "label": f.event.label()}},
                "ahead_steps": self.ahead_steps, "max_ahead_ms": self.max_ahead_ms,
                "violations": [list(v) for v in self.violations],
                "backtracks": self.backtracks, "elapsed_s": round(self.elapsed_s, 3)}


def timing_name(tolerance_ms: int | None) -> str:
    """How a timing rule is shown in reports."""
    if tolerance_ms is None:
        return "untimed (order and state only)"
    return "strict" if tolerance_ms == 0 else f"tolerance {tolerance_ms} ms"


@final
class Explainer:
    """Why a live event cannot be taken in a world: the `Unexplained` to report.

    Args:
        system: the checker's system.
        sigs: the checker events' signatures.
        ordinal: each live event's step number, by (node, index).
        strict: the timing rule is the checker's own (tolerance 0).
    """

    def __init__(self, system: System, sigs: Signatures, ordinal: dict[tuple[str, int], int],
                 *, strict: bool) -> None:
        self.system, self.sigs, self.ordinal, self.strict = system, sigs, ordinal, strict

    def unexplained(self, live: LiveEvent, reason: str, expected: str, seen: str) -> Unexplained:
        """`live` is unexplained for `reason`."""
        return Unexplained(self.ordinal[live.node, live.index], live, reason, expected, seen)

    def why_not(self, world: World, live: LiveEvent, matches: list[int],
                allowed: set[int]) -> Unexplained:
        """Why `live` cannot run in `world`: `matches` are the pending events with its
        signature, `allowed` the ones the timing rule enables (none of the matches)."""
        if live.kind is EventKind.START:
            return self.unexplained(live, OUTSIDE, "one @on_start per node, at t=0",
                                    f"{live.label()} again (a restart?)")
        events = world.events
        if matches:
            ev = events[matches[0]]
            first = self.system.rules.stream_head(events, ev)
            if first is not ev and not self.strict:
                return self.unexplained(live, ORDER, f"{self.label(first)} first (same stream)",
                                        f"{live.label()} at live t={live.t} ms")
            runnable = ", ".join(self.label(events[j]) for j in sorted(allowed)[:4])
            return self.unexplained(live, TIMING,
                                    f"the model runs {runnable} now (t*={world.next_time} ms); "
                                    f"this event is pending, due at t={ev.due} ms",
                                    f"{live.label()} ran at live t={live.t} ms")
        similar = [ev for ev in events if self.sigs.of(ev)[:4] == live_signature(live)[:4]]
        if similar:
            return self.unexplained(live, PAYLOAD,
                                    f"{self.label(similar[0])}: {summarise(similar[0].args)}",
                                    f"{live.summary} (args digest {live.args})")
        mine = [self.label(ev) for ev in events if self.system.names[ev.target] == live.node]
        return self.unexplained(live, NO_EVENT, f"pending for {live.node}: "
                                + (", ".join(mine[:6]) or "nothing"),
                                f"{live.label()}: {live.summary}")

    def label(self, ev: Event) -> str:
        """``node.handler(args) (kind from sender) due t=...`` of a checker event."""
        node, handler, kind, sender, _ = self.sigs.of(ev)
        source = "" if sender in ("", node) else f" from {sender}"
        return f"{node}.{handler}({summarise(ev.args, 40)}) ({kind}{source}) due t={ev.due}"

    def state(self, i: int, world: World) -> str:
        """Node `i`'s state in `world`, cut at 300 characters."""
        text = repr(self.system.decode(i, world.states[i]))
        return text if len(text) <= 300 else text[:297] + "..."


def earliest(why: Sequence[Unexplained]) -> Unexplained | None:
    """Of the reasons a dead end has, the one about the earliest live event; the others
    (one per other event, at most three) become its notes."""
    ordered = sorted(why, key=lambda u: u.event.line if u.event is not None else 0)
    if not ordered:
        return None
    first, others = ordered[0], list[str]()
    for u in ordered[1:]:
        if u.event is not None and u.event != first.event and len(others) < 3:
            others.append(f"{u.event.label()} [{u.event.where()}]: {u.reason}")
    return replace(first, notes=tuple(others))


def strict_line(strict: Validation) -> str:
    """One line: how far the checker's exact timing rules explain the run."""
    if strict.ok:
        return "strict timing (the checker's exact rules): every step enabled at its time"
    f = strict.failure
    assert f is not None
    what = f.event.label() if f.event is not None else "the start"
    return (f"strict timing (the checker's exact rules): {strict.explained} steps, then step "
            f"{f.step}: {what}: {f.reason}; expected {f.expected}")
