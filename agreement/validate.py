"""`twinfleet validate EVENTS SCENARIO`: is a recorded live run a path of the checker's System?

Theory of operation
===================

The live run is given as one event log per node (`agreement.events`): what
each node dispatched, in its own order, with its dispatch time, arguments,
`ctx.choose` answers and resulting state digest. The validator looks for an
interleaving of those per-node sequences that the checker's transition
relation (`checker.system.System`, the scenario's message rules) can run:

1. Start. Every node's log must begin with its `@on_start` events; their
   choices, concatenated in scenario order, select the checker's initial
   world, and each node's digest must equal the initial world's state.
2. Step. From world W and the per-node positions, the *candidates* are the
   next live events of the nodes whose dispatch time lies within
   ``window_ms`` of the earliest next live event (live clocks are shared but
   millisecond-coarse, so near-simultaneous events of different nodes may be
   taken in either order). A candidate is *explained* when W has a pending
   event with the same node, handler, kind, sender and argument digest that
   the timing rule enables (below); running it with the live choices must make
   the same choices (indices and option counts), fail exactly when the live
   handler failed, and give the node the live state digest.
3. Search. Candidates are tried in live-time order, depth first, with
   backtracking (a choice between two candidates can matter: an event may
   add a higher-priority event for another node). Pairs (world, positions)
   are visited once. The run is a path when every live event is explained;
   otherwise the report takes the deepest prefix found and names, of the
   live events that could not be taken after it, the earliest one, and why.

Timing rule (`tolerance_ms`). Live time is continuous and the checker's is
logical, so the validator compares order and state, never absolute times.
``0`` (strict): the candidate must be enabled by the checker's own rules
(`checker.semantics`: earliest time t*, per-node handler priority, per-sender
FIFO under ``ros``, a node's equal-time timers in the order they were set).
``T > 0``: any pending event due at most T ms after t* may run, provided it is
the earliest-sent pending message of its *stream* under ``ros``: messages of
one kind from one sender to one handler of one node. Live, that order holds
at any timing (Zenoh keeps each publisher's order and a subscription's queue
is FIFO), while the checker's wider channel order (all messages of a sender
to a node) only holds among events of equal time and priority: the host
runs same-millisecond arrivals by handler priority. Events whose model
times differ by at most T ms may thus run in either order. ``None``
(untimed): the same with T infinite, a check of causality, per-channel order
and state, blind to the model's timing. Whatever the rule, the report gives
how far ahead of the model's clock the path had to run events (``ahead``:
the event's logical due time minus t*): the timing gap between run and model.

Latency and faults. A scenario's ``check.latency`` and ``check.faults``
(drop, duplicate) are branches of the checker that no live node records: the
live log holds only each handler's own `ctx.choose` answers. Each step first
takes the checker's first branch on its effects (no delay, delivered once)
and leaves every other branch as a sibling to try on backtracking, so a live
delivery that came late may be explained by a delayed one. Branches on the
messages of the `@on_start` handlers give one initial world each, tried in
turn. Crash faults are refused (a live run shows a crash as a restart).

Reasons a step is unexplained: ``model drift`` (no such pending event, a
different message, different choices, a different state, a failure on one
side only), ``order`` (an earlier message of the same channel is pending:
a lost message), ``timing outside the model`` (the event is pending but the
timing rule does not enable it yet), ``startup`` (a node handled something
before its `@on_start`, which the model runs for every node at t=0 first)
and ``outside the model`` (liveliness changes, node restarts).
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, final

from twinfleet.agreement.events import (
    EventLogError,
    EventLogFile,
    LiveEvent,
    Signatures,
    live_signature,
    load_events,
    refuse_unreplayable,
)
from twinfleet.checker.check import load
from twinfleet.checker.choices import SplitChooser
from twinfleet.checker.commands import BAD_INPUT
from twinfleet.checker.properties import PropertySet
from twinfleet.checker.system import System
from twinfleet.checker.world import MESSAGE_KINDS, Event, World
from twinfleet.runtime.replay_gate import state_digest, summarise

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

    def summary(self) -> str:
        """A human-readable report."""
        head = (f"twinfleet validate {self.events_path} {self.scenario} "
                f"(semantics {self.semantics}, timing {self.timing})")
        if self.ok:
            verdict = (f"VALID: the live run is a path of the checker's transition relation: "
                       f"all {self.events} events explained")
        else:
            verdict = (f"NOT EXPLAINED: {self.explained} of {self.events} events explained; "
                       "first unexplained step:")
        lines = [head, verdict]
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


def validate(events: str | Path | EventLogFile, scenario_path: str | Path, *,
             semantics: str | None = None, tolerance_ms: int | None = 0, window_ms: int = 5,
             max_backtracks: int = 20_000) -> Validation:
    """Check that the live run logged in `events` is a path of the scenario's System.

    Args:
        events: an event log path (`twinfleet launch --record-events`) or a loaded log.
        scenario_path: the scenario the run used.
        semantics: checker message rules (default: the scenario's).
        tolerance_ms: the timing rule (module docstring): 0 strict, None untimed.
        window_ms: live events this close to the earliest next one may be taken first.
        max_backtracks: give up the interleaving search after this many dead ends.

    Raises:
        EventLogError, ScenarioError: unreadable inputs.
        ValueError: the scenario injects crash faults, which a live run shows as restarts.
    """
    started = time.monotonic()
    log = events if isinstance(events, EventLogFile) else load_events(events)
    scenario = load(scenario_path, semantics=semantics)
    system = System(scenario)
    refuse_unreplayable(system, gated=False)
    search = _Search(system, log, tolerance_ms, window_ms, max_backtracks)
    events_count = sum(1 for e in log.events if e.kind != "start")
    result = Validation(log.path, str(scenario_path), system.semantics.name,
                        timing_name(tolerance_ms), events_count, 0)
    search.run(result)
    result.elapsed_s = time.monotonic() - started
    return result


@final
@dataclass
class _Frame:
    world: World
    pos: tuple[int, ...]
    options: list[tuple[int, int, tuple[int, ...]]]  # (node, event, branch prefix)
    why: list[Unexplained]
    ahead: int = 0  # how far ahead of t* the step that made this world ran
    label: str = ""  # that step's live event
    next: int = 0


@final
class _Search:
    """The depth-first search over interleavings (module docstring, steps 2 and 3)."""

    def __init__(self, system: System, log: EventLogFile, tolerance_ms: int | None,
                 window_ms: int, max_backtracks: int) -> None:
        self.system, self.log = system, log
        self.tolerance, self.window, self.max_backtracks = tolerance_ms, window_ms, max_backtracks
        self.sigs = Signatures(system)
        by_node = log.by_node()
        self.queues = [by_node.get(name, []) for name in system.names]
        self.props = PropertySet.from_scenario(system.scenario)
        later = [e for e in log.events if e.kind != "start"]
        self.ordinal = {(e.node, e.index): n for n, e in enumerate(later, start=1)}
        self.ordinal.update({(e.node, e.index): 0 for e in log.events if e.kind == "start"})
        self._best: tuple[int, Unexplained | None] = (-1, None)  # deepest dead end, and why
        self._deepest: list[_Frame] = []  # the path to it

    # ------------------------------------------------------------ driver

    def run(self, result: Validation) -> None:
        outside = self._outside()
        if outside is not None:
            result.failure = outside
            return
        visited: set[tuple[bytes, tuple[int, ...]]] = set()
        branches: tuple[int, ...] | None = ()
        while branches is not None:  # one initial world per branch of the start messages
            root, branches = self._start(branches)
            if isinstance(root, Unexplained):
                if self._best[1] is None:
                    self._best = (0, root)
                continue
            if (root.world.key, root.pos) in visited:
                continue
            visited.add((root.world.key, root.pos))
            found = self._search(root, visited, result)
            if found is not None:
                self._finish(result, found, None)
                return
            if result.backtracks > self.max_backtracks:
                break
        if not self._deepest:  # no initial world fits the log's start events
            result.failure = self._best[1]
            return
        self._finish(result, self._deepest, self._best[1])

    def _search(self, root: _Frame, visited: set[tuple[bytes, tuple[int, ...]]],
                result: Validation) -> list[_Frame] | None:
        """Depth-first from `root`: the whole path if one explains every live event, else
        None (`_best` and `_deepest` then hold the deepest dead end so far)."""
        total = sum(len(q) for q in self.queues)
        stack = [root]
        self._deepest = self._deepest or [root]
        while stack:
            frame = stack[-1]
            depth = len(stack) - 1
            if sum(frame.pos) == total:
                return list(stack)
            if frame.next >= len(frame.options):
                if depth > self._best[0] or self._best[1] is None:
                    self._best = (depth, _earliest(frame.why))
                    self._deepest = list(stack)
                stack.pop()
                result.backtracks += 1
                if result.backtracks > self.max_backtracks:
                    gave_up = (f"the search gave up after {self.max_backtracks} dead ends; "
                               "a path may still exist",)
                    best = self._best
                    if best[1] is not None:
                        self._best = (best[0], replace(best[1], notes=best[1].notes + gave_up))
                    break
                continue
            i, k, branches = frame.options[frame.next]
            frame.next += 1
            child = self._step(frame, i, k, branches)
            if isinstance(child, Unexplained):
                frame.why.append(child)
                continue
            key = (child.world.key, child.pos)
            if key not in visited:
                visited.add(key)
                stack.append(child)
        return None

    def _finish(self, result: Validation, path: list[_Frame], failure: Unexplained | None) -> None:
        result.failure = failure
        result.explained = len(path) - 1
        worst = max(path, key=lambda f: f.ahead)
        result.ahead_steps = sum(1 for f in path if f.ahead > 0)
        result.max_ahead_ms = worst.ahead
        if worst.ahead:
            result.max_ahead_at = f"step {path.index(worst)}: {worst.label}"
        seen: set[str] = set()
        for n, frame in enumerate(path):
            violation = self.props.check_world(self.system, frame.world)
            if violation is not None and violation.property not in seen:
                seen.add(violation.property)
                result.violations.append((n, violation.property,
                                          f"{violation.message}, after {frame.label}"))

    # ------------------------------------------------------------ start

    def _outside(self) -> Unexplained | None:
        restarts = self.log.header.get("restarts") or {}
        if restarts:
            node = sorted(restarts)[0]
            return Unexplained(0, None, OUTSIDE, "no node restarts (crash faults are not "
                               "validated)", f"{node} restarted {restarts[node]} time(s)")
        known = set(self.system.names)
        for ev in self.log.events:
            if ev.node not in known:
                return Unexplained(0, ev, OUTSIDE, f"nodes {sorted(known)}",
                                   f"events of node {ev.node}")
            if ev.kind == "liveliness":
                return Unexplained(0, ev, OUTSIDE, "no liveliness events (the checker has "
                                   "no liveliness changes)", ev.summary)
        return None

    def _start(self, branches: tuple[int, ...]
               ) -> tuple[_Frame | Unexplained, tuple[int, ...] | None]:
        """The initial world whose start messages take `branches`, and the next branches
        to try (None after the last; an unexplained start ends the enumeration too)."""
        choices: list[int] = []
        pos = []
        for i, node in enumerate(self.system.nodes):
            n = len(node.spec().of_kind("start"))
            head = self.queues[i][:n]
            early = next((e for e in head if e.kind != "start"), None)
            if early is not None:
                return Unexplained(0, early, START, f"{node.name} runs its @on_start first "
                                   "(the checker starts every node at t=0 before any event)",
                                   f"{early.label()} before {node.name}'s @on_start"), None
            if len(head) < n:
                return Unexplained(0, None, START, f"{n} @on_start event(s) of {node.name}",
                                   f"{len(head)} in the log (the node never started?)"), None
            for e in head:
                choices += e.choices
            pos.append(n)
        chooser = SplitChooser(choices, branches)
        init = self.system.initial_world(chooser=chooser)
        for i, name in enumerate(self.system.names):
            if pos[i] == 0:
                continue
            last = self.queues[i][pos[i] - 1]
            digest = state_digest(init.world.states[i])
            if digest != last.digest:
                return Unexplained(0, last, STATE, f"{name}'s initial state, digest {digest}: "
                                   f"{self._state(i, init.world)}", f"digest {last.digest}"), None
        if init.failure is not None:
            return Unexplained(0, None, ERROR, "start handlers without failure",
                               str(init.failure)), None
        pos_t = tuple(pos)
        options, why = self._options(init.world, pos_t)
        return _Frame(init.world, pos_t, options, why), chooser.next_branch_prefix()

    # ------------------------------------------------------------ steps

    def _step(self, frame: _Frame, i: int, k: int, branches: tuple[int, ...]
              ) -> _Frame | Unexplained:
        world = frame.world
        live = self.queues[i][frame.pos[i]]
        ev = world.events[k]
        # The live node made the handler's choices; the checker's own branches on the
        # effects (latency, drop, duplicate) are searched: first the first, then the others.
        chooser = SplitChooser(live.choices, branches)
        t = self.system.run(world, k, chooser)
        made = (tuple(chooser.handler_indices), tuple(chooser.handler_options))
        if made != (live.choices, live.options) or (
                t.failure is not None and "nondeterministic choices" in t.failure.message):
            return Unexplained(self.ordinal[live.node, live.index], live, CHOICES,
                               f"choices {list(made[0])} of options {list(made[1])}",
                               f"choices {list(live.choices)} of options {list(live.options)}")
        if (t.failure is None) != (live.error is None):
            return Unexplained(self.ordinal[live.node, live.index], live, ERROR, str(t.failure) if t.failure else "no failure",
                               live.error or "no failure")
        digest = state_digest(t.world.states[i])
        if digest != live.digest and live.error is None:
            return Unexplained(self.ordinal[live.node, live.index], live, STATE,
                               f"digest {digest}: {self._state(i, t.world)}",
                               f"digest {live.digest}")
        sibling = chooser.next_branch_prefix()  # tried if this branch dead-ends
        if sibling is not None:
            frame.options.insert(frame.next, (i, k, sibling))
        pos = (*frame.pos[:i], frame.pos[i] + 1, *frame.pos[i + 1:])
        options, why = self._options(t.world, pos)
        now = world.next_time  # t* of the world the event ran in (0 is a time, not 'none')
        ahead = ev.due - (ev.due if now is None else now)
        return _Frame(t.world, pos, options, why, ahead, f"{live.label()} [{live.where()}]")

    def _options(self, world: World, pos: tuple[int, ...]
                 ) -> tuple[list[tuple[int, int]], list[Unexplained]]:
        heads = [(q[p].t, i, q[p]) for i, (q, p) in enumerate(zip(self.queues, pos, strict=True))
                 if p < len(q)]
        if not heads:
            return [], []
        first = min(h[0] for h in heads)
        allowed = self._enabled(world.events)
        options, why = [], []
        for _, i, live in sorted(h for h in heads if h[0] <= first + self.window):
            sig = live_signature(live)
            matches = [k for k, ev in enumerate(world.events) if self.sigs.of(ev) == sig]
            ok = [k for k in matches if k in allowed]
            if ok:
                options.append((i, ok[0], ()))
            else:
                why.append(self._why_not(world, live, matches, allowed))
        return options, why

    def _enabled(self, events: Sequence[Event]) -> set[int]:
        if not events:
            return set()
        if self.tolerance == 0:
            return set(self.system.semantics.enabled(events))
        limit = None if self.tolerance is None else events[0].due + self.tolerance
        return _enabled_within(events, limit, self.system.semantics.fifo)

    # ------------------------------------------------------------ explanations

    def _why_not(self, world: World, live: LiveEvent, matches: list[int],
                 allowed: set[int]) -> Unexplained:
        if live.kind == "start":
            return Unexplained(self.ordinal[live.node, live.index], live, OUTSIDE, "one @on_start per node, at t=0",
                               f"{live.label()} again (a restart?)")
        events = world.events
        if matches:
            ev = events[matches[0]]
            first = _channel_head(events, ev)
            if first is not ev and self.tolerance != 0:
                return Unexplained(self.ordinal[live.node, live.index], live, ORDER, f"{self._label(first)} first (same stream)",
                                   f"{live.label()} at live t={live.t} ms")
            now = world.next_time
            runnable = ", ".join(self._label(events[j]) for j in sorted(allowed)[:4])
            return Unexplained(self.ordinal[live.node, live.index], live, TIMING,
                               f"the model runs {runnable} now (t*={now} ms); this event is "
                               f"pending, due at t={ev.due} ms",
                               f"{live.label()} ran at live t={live.t} ms")
        similar = [ev for ev in events if self.sigs.of(ev)[:4] == live_signature(live)[:4]]
        if similar:
            return Unexplained(self.ordinal[live.node, live.index], live, PAYLOAD,
                               f"{self._label(similar[0])}: {summarise(similar[0].args)}",
                               f"{live.summary} (args digest {live.args})")
        mine = [self._label(ev) for ev in events if self.system.names[ev.target] == live.node]
        return Unexplained(self.ordinal[live.node, live.index], live, NO_EVENT,
                           "pending for " + live.node + ": " + (", ".join(mine[:6]) or "nothing"),
                           f"{live.label()}: {live.summary}")

    def _label(self, ev: Event) -> str:
        node, handler, kind, sender, _ = self.sigs.of(ev)
        source = "" if sender in ("", node) else f" from {sender}"
        args = summarise(ev.args, 40)
        return f"{node}.{handler}({args}) ({kind}{source}) due t={ev.due}"

    def _state(self, i: int, world: World) -> str:
        text = repr(self.system.decode(i, world.states[i]))
        return text if len(text) <= 300 else text[:297] + "..."


def _stream(ev: Event) -> tuple[int, int, str, str] | None:
    """The live FIFO stream of a message (module docstring); None for timers."""
    return (ev.sender, ev.target, ev.kind, ev.method) if ev.kind in MESSAGE_KINDS else None


def _earliest(why: Sequence[Unexplained]) -> Unexplained | None:
    """Of the reasons a dead end has, the one about the earliest live event; the others
    (one per other event, at most three) become its notes."""
    ordered = sorted(why, key=lambda u: u.event.line if u.event is not None else 0)
    if not ordered:
        return None
    first, others = ordered[0], []
    for u in ordered[1:]:
        if u.event is not None and u.event != first.event and len(others) < 3:
            others.append(f"{u.event.label()} [{u.event.where()}]: {u.reason}")
    return replace(first, notes=tuple(others))


def _channel_head(events: Sequence[Event], ev: Event) -> Event:
    """The earliest-sent pending message of `ev`'s stream (`ev` itself for timers)."""
    stream = _stream(ev)
    if stream is None:
        return ev
    return min((e for e in events if _stream(e) == stream), key=lambda e: (e.due, e.rank))


def _enabled_within(events: Sequence[Event], limit: int | None, fifo: bool) -> set[int]:
    """Events due by `limit` (None: any) that are the earliest-sent message of their stream."""
    first: dict[tuple[int, int, str, str], int] = {}
    for j, ev in enumerate(events):
        stream = _stream(ev) if fifo else None
        if stream is not None:
            k = first.get(stream)
            if k is None or (ev.due, ev.rank) < (events[k].due, events[k].rank):
                first[stream] = j
    heads = set(first.values())
    return {j for j, ev in enumerate(events) if (limit is None or ev.due <= limit)
            and (j in heads or not fifo or _stream(ev) is None)}


def validate_command(args: Any) -> int:
    """`twinfleet validate EVENTS SCENARIO`: exit 0 valid, 1 a step is unexplained, 2 bad input.

    Without ``--tolerance-ms`` the verdict is the order-and-state check; the report
    then also gives the first step outside the checker's exact timing rules.
    """
    try:
        log = load_events(args.events)
        result = validate(log, args.scenario, semantics=args.semantics,
                          tolerance_ms=args.tolerance_ms, window_ms=args.window_ms)
        strict = None
        if args.tolerance_ms is None:
            strict = validate(log, args.scenario, semantics=args.semantics, tolerance_ms=0,
                              window_ms=args.window_ms, max_backtracks=2_000)
    except (*BAD_INPUT, EventLogError, ValueError, OSError) as exc:
        print(f"twinfleet validate: {exc}", file=sys.stderr)
        return 2
    if args.json:
        record = result.to_json()
        record["strict"] = None if strict is None else strict.to_json()
        print(json.dumps(record, indent=1))
    else:
        print(result.summary())
        if strict is not None:
            print(_strict_line(strict))
    return 0 if result.ok else 1


def _strict_line(strict: Validation) -> str:
    if strict.ok:
        return "strict timing (the checker's exact rules): every step enabled at its time"
    f = strict.failure
    assert f is not None
    what = f.event.label() if f.event is not None else "the start"
    return (f"strict timing (the checker's exact rules): {strict.explained} steps, then step "
            f"{f.step}: {what}: {f.reason}; expected {f.expected}")
