"""`twinfleet validate EVENTS SCENARIO`: is a recorded live run a path of the checker's System?

Theory of operation
===================

The live run is given as one event log per node (`agreement.events`): what
each node dispatched, in its own order, with its dispatch time, arguments,
`ctx.choose` answers and resulting state digest. The validator looks for an
interleaving of those per-node sequences that the checker's transition
relation (`checker.system.System`: its actions and its one step function,
under the scenario's message rules) can run:

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
   add a higher-priority event for another node). Triples (world, positions,
   the world's time) are visited once: a world's key is up to time shift, and
   a node that stored a tick's `ctx.now()` makes worlds a shift apart differ. The run is a path when every live event is explained;
   otherwise the report takes the deepest prefix found and names, of the
   live events that could not be taken after it, the earliest one, and why.

Timing rule (`tolerance_ms`). Live time is continuous and the checker's is
logical, so the validator compares order and state, never absolute times.
``0`` (strict): the candidate must be enabled by the checker's own rules
(`checker.semantics`: earliest time t*, per-node handler priority, per-sender
FIFO under ``ros``, a node's equal-time timers in the order they were set).
``T > 0``: the relaxed rule of `checker.semantics` (`Rules.enabled_within`):
any pending event due at most T ms after t* may run, provided it is the
earliest-sent pending message of its *stream* under ``ros`` (messages of one
kind from one sender to one handler of one node), so events whose model
times differ by at most T ms may run in either order. ``None`` (untimed): the
same with T infinite, a check of causality, per-stream order and state,
blind to the model's timing; its timers may also be as late as the run's
skipped `@every` periods show (`skipped_lateness`: a node that fell a period
or more behind skips the missed ticks, Rule 7 of `checker.semantics`, and the
checker branches over them). Whatever the rule, the report gives
how far ahead of the model's clock the path had to run events (``ahead``:
the event's logical due time minus t*): the timing gap between run and model.

Liveliness. A node's liveliness handler runs live for every peer appearing
at the start and, at a crash, going and coming back (the checker's events);
at the run's end it may also hear peers leave as the fleet shuts down, which
the model does not have: such a "gone" of a node that never restarted is
taken without a checker step.

KEEP_LAST. The live log does not say which messages a subscription's depth
dropped (`checker.semantics` Rule 6): a pending delivery the checker may drop
is one more option of every step, tried after the live events (under the
timing rule's tolerance, as events may run ahead); it consumes no live event.

Latency and faults. A scenario's ``check.latency`` and ``check.faults``
(drop, duplicate) are branches of the checker that no live node records: the
live log holds only each handler's own `ctx.choose` answers. Each step first
takes the checker's first branch on its effects (no delay, delivered once)
and leaves every other branch as a sibling to try on backtracking, so a live
delivery that came late may be explained by a delayed one. Branches on the
messages of the `@on_start` handlers give one initial world each, tried in
turn. A node that died and was respawned live has a ``crash`` record in its
log, then its new process's start events: that is the checker's `Crash` action
(allowed by ``check.faults.crash``), whose restart must make the same start
choices and reach the same state.

Crash window. A node writes a handler's log line before it publishes the
handler's outputs (the line is flushed first, so the log never misses a run
whose messages others received). A process killed between the two leaves a
logged run whose outputs nobody got. The validator takes such a run — the last
one before a ``crash`` record — either as run (tried first) or as cut off: the
model's crash came before it, and the event it handled was lost with the node,
as the checker's `Crash` discards what is pending to it. A node that keeps its
state across crashes must then restart in the state from before that run, so a
cut-off run that changed a durable state stays unexplained.

Reasons a step is unexplained: ``model drift`` (no such pending event, a
different message, different choices, a different state, a failure on one
side only), ``order`` (an earlier message of the same channel is pending:
a lost message), ``timing outside the model`` (the event is pending but the
timing rule does not enable it yet), ``startup`` (a node handled something
before its `@on_start`, which the model runs for every node at t=0 first)
and ``outside the model`` (a restart the scenario's crash faults do not allow).
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
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
from twinfleet.agreement.validation import (
    CHOICES,
    ERROR,
    NO_EVENT,
    ORDER,
    OUTSIDE,
    PAYLOAD,
    START,
    STATE,
    TIMING,
    Explainer,
    Unexplained,
    Validation,
    earliest,
    timing_name,
)
from twinfleet.checker.choices import PrefixChooser, SplitChooser
from twinfleet.checker.commands import bad_input_errors
from twinfleet.checker.driver import load
from twinfleet.checker.properties import PropertySet
from twinfleet.checker.system import System
from twinfleet.checker.transition import Crash, Drop, RunEvent
from twinfleet.checker.world import World
from twinfleet.runtime.contract.kinds import EXIT_BAD_INPUT, EventKind, FailureKind
from twinfleet.runtime.contract.messages import NodeAlive
from twinfleet.runtime.core.eventlog import payload_digest, state_digest
from twinfleet.runtime.scenario.overrides import override_words

__all__ = ["CHOICES", "ERROR", "NO_EVENT", "ORDER", "OUTSIDE", "PAYLOAD", "START", "STATE",
           "TIMING", "Unexplained", "Validation", "timing_name", "validate", "validate_command"]


def validate(events: str | Path | EventLogFile, scenario_path: str | Path, *,
             semantics: str | None = None, tolerance_ms: int | None = 0, window_ms: int = 5,
             max_backtracks: int = 20_000, params: Sequence[str] = ()) -> Validation:
    """Check that the live run logged in `events` is a path of the scenario's System.

    Args:
        events: an event log path (`twinfleet launch --record-events`) or a loaded log.
        scenario_path: the scenario the run used.
        semantics: checker message rules (default: the scenario's).
        tolerance_ms: the timing rule (module docstring): 0 strict, None untimed.
        window_ms: live events this close to the earliest next one may be taken first.
        max_backtracks: give up the interleaving search after this many dead ends.
        params: the parameter overrides the run was launched with (``r1.speed:=0.4``).

    Raises:
        EventLogError, ScenarioError: unreadable inputs.
        ValueError: the scenario injects crash faults, which a live run shows as restarts.
    """
    started = time.monotonic()
    log = events if isinstance(events, EventLogFile) else load_events(events)
    scenario = load(scenario_path, semantics=semantics, params=params)
    system = System(scenario)
    late = skipped_lateness(system, log) if tolerance_ms is None else 0
    if late:  # untimed: as late as the run's skipped ticks show (Rule 7)
        low, high = scenario.check.timer_lateness or (0, 0)
        system = System(scenario, timer_lateness=(low, max(high, late)))
    refuse_unreplayable(system, gated=False)
    search = _Search(system, log, tolerance_ms, window_ms, max_backtracks)
    events_count = sum(1 for e in log.events if e.kind is not EventKind.START)
    result = Validation(log.path, str(scenario_path), system.semantics.value,
                        timing_name(tolerance_ms), events_count, 0)
    search.run(result)
    result.elapsed_s = time.monotonic() - started
    return result


def skipped_lateness(system: System, log: EventLogFile) -> int:
    """The least timer lateness that explains every skip of missed `@every` periods in
    `log` (0: none): a tick due at d whose next logged tick is at d' > d + period was
    taken at least d' - period - d ms late (`runtime.contract.rules.next_tick`)."""
    late = 0
    for name, events in log.by_node().items():
        i = system.index.get(name)
        last: dict[str, int] = {}
        for ev in events:
            if ev.kind is EventKind.CRASH:  # a new process arms its timers afresh
                last.clear()
            if ev.kind is not EventKind.PERIODIC or ev.due is None or i is None:
                continue
            period = system.topology.period(i, ev.handler)[0]
            before = last.get(ev.handler)
            if before is not None and ev.due - before > period:
                late = max(late, ev.due - before - period)
            last[ev.handler] = ev.due
    return late


Option = tuple[int, int, tuple[int, ...]]  # (node, pending event, branch prefix)
DROPPED = -1  # the `node` of an option that drops the pending event (KEEP_LAST)
RESTART = -1  # the `pending event` of an option that crashes and restarts the node
LEFT = -2  # the `pending event` of an option that takes a peer leaving at shutdown
CUT = -3  # the `pending event` of an option that takes a run as cut off by the crash after it
_Seen = tuple[int | bytes, tuple[int, ...], int | None]  # `_Frame.seen`


@final
@dataclass
class _Frame:
    world: World
    pos: tuple[int, ...]
    options: list[Option]
    why: list[Unexplained]
    ahead: int = 0  # how far ahead of t* the step that made this world ran
    label: str = ""  # that step's live event
    next: int = 0

    @property
    def seen(self) -> _Seen:
        """What the search visits once: the world, the live positions and the world's
        time. A world's key is up to time shift, but a node may have stored the time
        (`ctx.now()` of a tick), so worlds a shift apart (a tick on time, or late with the
        missed periods skipped) may have different futures: they are kept apart."""
        return self.world.key, self.pos, self.world.next_time


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
        later = [e for e in log.events if e.kind is not EventKind.START]
        ordinal = {(e.node, e.index): n for n, e in enumerate(later, start=1)}
        ordinal.update({(e.node, e.index): 0 for e in log.events if e.kind is EventKind.START})
        self.explain = Explainer(system, self.sigs, ordinal, strict=tolerance_ms == 0)
        self._best: tuple[int, Unexplained | None] = (-1, None)  # deepest dead end, and why
        self._deepest: list[_Frame] = []  # the path to it

    # ------------------------------------------------------------ driver

    def run(self, result: Validation) -> None:
        outside = self._outside()
        if outside is not None:
            result.failure = outside
            return
        visited: set[_Seen] = set()
        branches: tuple[int, ...] | None = ()
        while branches is not None:  # one initial world per branch of the start messages
            root, branches = self._start(branches)
            if isinstance(root, Unexplained):
                if self._best[1] is None:
                    self._best = (0, root)
                continue
            if root.seen in visited:
                continue
            visited.add(root.seen)
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

    def _search(self, root: _Frame, visited: set[_Seen],
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
                    self._best = (depth, earliest(frame.why))
                    self._deepest = list(stack)
                stack.pop()
                result.backtracks += 1
                if result.backtracks > self.max_backtracks:
                    self._give_up()
                    break
                continue
            i, k, branches = frame.options[frame.next]
            frame.next += 1
            child = self._step(frame, i, k, branches)
            if isinstance(child, Unexplained):
                frame.why.append(child)
                continue
            key = child.seen
            if key not in visited:
                visited.add(key)
                stack.append(child)
        return None

    def _give_up(self) -> None:
        gave_up = (f"the search gave up after {self.max_backtracks} dead ends; "
                   "a path may still exist",)
        depth, why = self._best
        if why is not None:
            self._best = (depth, replace(why, notes=why.notes + gave_up))

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
        known = set(self.system.names)
        for ev in self.log.events:
            if ev.node not in known:
                return Unexplained(0, ev, OUTSIDE, f"nodes {sorted(known)}",
                                   f"events of node {ev.node}")
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
            early = next((e for e in head if e.kind is not EventKind.START), None)
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
                                   f"{self.explain.state(i, init.world)}",
                                   f"digest {last.digest}"), None
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
        if k == RESTART:
            return self._restart(frame, i, branches)
        if k == CUT:  # the crash came before the run's outputs left: the model's crash first
            pos = (*frame.pos[:i], frame.pos[i] + 1, *frame.pos[i + 1:])
            options, why = self._options(world, pos)
            live = self.queues[i][frame.pos[i]]
            return _Frame(world, pos, options, why, 0, f"{live.label()} (cut off by the crash)")
        if k == LEFT:  # the node heard a peer leave at the run's end: nothing to model
            pos = (*frame.pos[:i], frame.pos[i] + 1, *frame.pos[i + 1:])
            options, why = self._options(world, pos)
            live = self.queues[i][frame.pos[i]]
            return _Frame(world, pos, options, why, 0, f"{live.label()} (shutdown)")
        if i == DROPPED:  # KEEP_LAST drops: no live event, the node just never ran it
            t = self.system.step(world, Drop(k), PrefixChooser())
            options, why = self._options(t.world, frame.pos)
            return _Frame(t.world, frame.pos, options, why, 0, f"drop of {t.event.method}")
        live = self.queues[i][frame.pos[i]]
        ev = world.events[k]
        # The live node made the handler's choices; the checker's own branches on the
        # effects (latency, drop, duplicate) are searched: first the first, then the others.
        chooser = SplitChooser(live.choices, branches)
        t = self.system.step(world, RunEvent(k), chooser)
        made = (tuple(chooser.handler_indices), tuple(chooser.handler_options))
        failure = t.failure
        if made != (live.choices, live.options) or (
                failure is not None and failure.kind is FailureKind.CHOICE_MISMATCH):
            return self.explain.unexplained(
                live, CHOICES, f"choices {list(made[0])} of options {list(made[1])}",
                f"choices {list(live.choices)} of options {list(live.options)}")
        if (failure is None) != (live.error is None):
            return self.explain.unexplained(live, ERROR, str(failure) if failure else
                                            "no failure", live.error or "no failure")
        digest = state_digest(t.world.states[i])
        if digest != live.digest and live.error is None:
            return self.explain.unexplained(live, STATE, f"digest {digest}: "
                                            f"{self.explain.state(i, t.world)}",
                                            f"digest {live.digest}")
        sibling = chooser.next_branch_prefix()  # tried if this branch dead-ends
        if sibling is not None:
            frame.options.insert(frame.next, (i, k, sibling))
        pos = (*frame.pos[:i], frame.pos[i] + 1, *frame.pos[i + 1:])
        options, why = self._options(t.world, pos)
        now = world.next_time  # t* of the world the event ran in (0 is a time, not 'none')
        ahead = ev.due - (ev.due if now is None else now)
        return _Frame(t.world, pos, options, why, ahead, f"{live.label()} [{live.where()}]")

    def _leaving(self, live: LiveEvent) -> bool:
        """Whether `live` tells of a node leaving as the fleet shuts down: the peer went
        away and did nothing after it (the run's end is outside the model). Tried only when
        the model has no such event, so a crash's leave (which the model has) is not it."""
        if live.kind is not EventKind.LIVELINESS or live.sender not in self.system.index:
            return False
        gone = payload_digest((NodeAlive(live.sender, False),))
        queue = self.queues[self.system.index[live.sender]]
        return live.args == gone and not any(e.t > live.t for e in queue)

    def _cut_off(self, i: int, p: int) -> bool:
        """Whether node i's p-th event is its last logged run before a crash record: it logs
        a run before it publishes the run's outputs, so a process that died in between left
        the log line but sent nothing (module docstring, "Crash window")."""
        queue = self.queues[i]
        return p + 1 < len(queue) and queue[p + 1].kind is EventKind.CRASH

    def _restart(self, frame: _Frame, i: int, branches: tuple[int, ...]) -> _Frame | Unexplained:
        """A live crash record and the new process's start events: the checker's `Crash`."""
        world, queue, p = frame.world, self.queues[i], frame.pos[i]
        n = len(self.system.nodes[i].spec().of_kind("start"))
        starts = queue[p + 1:p + 1 + n]
        crash = queue[p]
        if len(starts) < n or any(e.kind is not EventKind.START for e in starts):
            return self.explain.unexplained(crash, START, f"{n} @on_start event(s) after the "
                                            "restart", "other events")
        choices = [c for e in starts for c in e.choices]
        chooser = SplitChooser(choices, branches)
        t = self.system.step(world, Crash(i), chooser)
        if t.failure is not None:
            return self.explain.unexplained(crash, ERROR, str(t.failure), "a restart")
        digest = state_digest(t.world.states[i])
        if starts and digest != starts[-1].digest:
            return self.explain.unexplained(starts[-1], STATE, f"digest {digest}: "
                                            f"{self.explain.state(i, t.world)}",
                                            f"digest {starts[-1].digest}")
        sibling = chooser.next_branch_prefix()
        if sibling is not None:
            frame.options.insert(frame.next, (i, RESTART, sibling))
        pos = (*frame.pos[:i], p + 1 + n, *frame.pos[i + 1:])
        options, why = self._options(t.world, pos)
        return _Frame(t.world, pos, options, why, 0, f"{crash.node} crashed and restarted "
                      f"[{crash.where()}]")

    def _options(self, world: World, pos: tuple[int, ...]
                 ) -> tuple[list[Option], list[Unexplained]]:
        heads = [(q[p].t, i, q[p]) for i, (q, p) in enumerate(zip(self.queues, pos, strict=True))
                 if p < len(q)]
        if not heads:
            return [], []
        first = min(h[0] for h in heads)
        allowed = self._enabled(world)
        options: list[Option] = []
        why = []
        # A crash record carries the restart's time, not the death's (which no log has):
        # it may be taken whenever it heads its node's log.
        for _, i, live in sorted(h for h in heads if h[0] <= first + self.window
                                 or h[2].kind is EventKind.CRASH):
            if live.kind is EventKind.CRASH:
                if Crash(i) in self.system.actions(world):
                    options.append((i, RESTART, ()))
                else:
                    why.append(self.explain.unexplained(
                        live, OUTSIDE, f"a crash of {live.node} the scenario allows now "
                        "(check.faults.crash: its nodes and max)", f"{live.node} restarted"))
                continue
            sig = live_signature(live)
            matches = [k for k, ev in enumerate(world.events) if self.sigs.of(ev) == sig]
            ok = [k for k in matches if k in allowed]
            if ok:
                options.append((i, ok[0], ()))
            elif self._leaving(live):
                options.append((i, LEFT, ()))
            else:
                why.append(self.explain.why_not(world, live, matches, allowed))
            if self._cut_off(i, pos[i]):
                options.append((i, CUT, ()))
        # Tried after every live event: a message KEEP_LAST may have dropped (Rule 6).
        drops = self.system.rules.droppable(world.events, self.tolerance)
        options += [(DROPPED, k, ()) for k in drops]
        return options, why

    def _enabled(self, world: World) -> set[int]:
        """The pending events the timing rule lets run: strictly, the model's own actions."""
        if self.tolerance == 0:
            return {a.index for a in self.system.actions(world) if isinstance(a, RunEvent)}
        return self.system.rules.enabled_within(world.events, self.tolerance)


def validate_command(args: Any) -> int:
    """`twinfleet validate EVENTS SCENARIO [NAME:=VALUE...]`: exit 0 a path of the exact
    model, 1 a step is unexplained, 2 bad input, 3 a path only if timing is ignored.

    Unless ``--tolerance-ms 0`` judged the run by the exact rules already, the run is
    judged by them too, and the verdict (first line, and exit code) says which held.
    """
    bad_input: tuple[type[Exception], ...] = (*bad_input_errors(), EventLogError, ValueError,
                                              OSError)
    try:
        params = override_words("validate", args.overrides, args.param)
        log = load_events(args.events)
        result = validate(log, args.scenario, semantics=args.semantics,
                          tolerance_ms=args.tolerance_ms, window_ms=args.window_ms,
                          params=params)
        strict = None
        if args.tolerance_ms != 0:
            strict = validate(log, args.scenario, semantics=args.semantics, tolerance_ms=0,
                              window_ms=args.window_ms, max_backtracks=2_000, params=params)
    except bad_input as exc:
        print(f"twinfleet validate: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    if args.json:
        record = result.to_json()
        record["strict"] = None if strict is None else strict.to_json()
        record["verdict"] = result.verdict(strict)
        record["exit_code"] = result.exit_code(strict)
        print(json.dumps(record, indent=1))
    else:
        print(result.summary(strict))
    return result.exit_code(strict)
