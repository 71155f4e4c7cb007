"""The live verdict: a scenario's properties judged on a running fleet (runtime verification).

Theory of operation. Every node reports its state after each handler that
changed it or failed (`runtime.core.state_report`); the launcher feeds the reports
to a `LiveJudge`, which keeps the last reported state of every node (it
starts from the initial states, built here from the scenario as the checker
builds them) and evaluates the properties on that view in the order reports
arrive — the same expressions, in the same safe language, as the checker
(`runtime.scenario.property_eval`):

- `invariant`: after each report that changed a node the expression reads; the
  first violation is kept with its time, the states of the nodes it reads and
  the event that caused it (the report's handler run);
- `no_failure`: always checked, as in the checker: a handler that raised or
  called ``ctx.fail`` violates it (named after the scenario's `no_failure`
  property, else ``no_failure``);
- `eventually`: holds once the expression was true on some report; judged at
  the end of the run (or as soon as it held);
- `within`: holds if it was true no later than ``within_ms`` of fleet time
  (0 is the launcher's epoch, as in the checker), violated as soon as a report
  comes later while it never was;
- `deadlock` and `quiescence` need to know that no event is pending anywhere,
  which a live run cannot see: they are listed as not judged live.

A cross-node invariant is evaluated on the monitor's view of the fleet: each
node's last reported state, in arrival order. Reports of one node arrive in
order (one publisher, reliable); two nodes' reports are ordered only by when
the launcher hears them, so the view is a cut of the fleet up to transport
latency (tens of µs here against handler periods of ms).

Honest verdicts. A run whose nodes lost samples a verdict depends on says so:
`Verdict` is INCONCLUSIVE (exit 3) when a node's final statistics show a
transport hand-off overflow, sequence gaps on reliable topics, KEEP_LAST drops
on a RELIABLE (lossless) subscription, a sample refused for any `Rejection`
reason, or timers released later than the node's stall threshold
(`runtime.core.node_core`: twice its shortest timer period — `@every` or a
positive `ctx.after` delay, the scan period for the map server — so a node
that late has missed a whole tick, e.g. a robot that moved without a scan;
never below `stall_floor_ms`, 100 ms of wall time); or when state reports
were lost, a running node did not answer for its statistics or sent ones
that cannot be read (`NodeStatistics.from_dict` refused them), or a property
took longer than its evaluation budget. Such a run is inconclusive even when
a property was seen violated (listed in the details): a robot that teleported
after a stall collides because of the stall, not of its code.

External input. A fleet may take input from outside it: an operator's `topic pub` or
`service call` (signed with the owner's operator login, sender `OPERATOR_SENDER`), the
ROS 2 bridge on the topics its nodes declare external (a robot's goal from RViz:
`runtime.core.guard`), recorded samples `play --into-fleet` injects. They do not change
how a run is judged — they are inputs, as a scenario's parameters are — but a verdict
whose nodes took any says so first, in one detail line naming each node, what came in
on which topic or service and from where (`external_input_line`): the run is then not
one the checked model describes.

Result (`Verdict.status`, a `runtime.contract.kinds.Status`, and its exit code):
``holds`` 0, ``violated`` 1 (the property named), ``error`` 2 (a property raised:
a scenario mistake, as `check` says), ``inconclusive`` 3, ``interrupted`` 130.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Final, final

from twinfleet.runtime.contract.kinds import Status
from twinfleet.runtime.contract.snapshot import restore
from twinfleet.runtime.core.state_report import StateReport
from twinfleet.runtime.core.statistics import NodeStatistics, Outside
from twinfleet.runtime.scenario.property_eval import (
    Expression,
    Overtime,
    parse_expression,
    time_limit,
)
from twinfleet.runtime.scenario.property_fields import nodes_read
from twinfleet.runtime.scenario.spec import PropertyConfig, Scenario

# The launcher's result line says these words (tests and users read them).
RESULT_WORDS: Final = {Status.HOLDS: "PASSED", Status.VIOLATED: "FAILED", Status.ERROR: "ERROR",
                       Status.INCONCLUSIVE: "INCONCLUSIVE", Status.INTERRUPTED: "interrupted",
                       Status.BREACH: "CONTRACT BREACH"}
EVAL_BUDGET_S: Final = 1.0  # wall seconds one evaluation may take in the launcher
STALL_FLOOR_WALL_MS: Final = 100  # a stall threshold is never below this much wall time
_STATE_CHARS: Final = 300  # of each node's state in a violation's description


@final
@dataclass(frozen=True, slots=True)
class Verdict:
    """How a live run stands against its scenario's properties."""

    status: Status  # HOLDS, VIOLATED, BREACH, ERROR, INCONCLUSIVE or INTERRUPTED
    summary: str  # one line: what decided it
    details: tuple[str, ...] = ()  # the violation's states and event, the reasons, ...
    property_name: str | None = None  # the property violated

    @property
    def exit_code(self) -> int:
        """The command's exit code for this verdict (`runtime.contract.kinds`)."""
        return self.status.exit_code

    def lines(self) -> list[str]:
        """The result line and its details, for the launcher's summary."""
        return [f"result: {RESULT_WORDS[self.status]} ({self.summary})",
                *(f"  {d}" for d in self.details)]


@dataclass(slots=True)
class _Watch:
    """One property as the monitor follows it."""

    cfg: PropertyConfig
    expr: Expression | None
    reads: frozenset[str] | None  # node names the expression reads; None: all of them
    held: bool = False
    broken: str | None = None  # why it cannot be judged (overtime)


@final
@dataclass(frozen=True, slots=True)
class RunEnd:
    """What the launcher knows at the end of a run, besides the reports."""

    reason: str
    interrupted: bool = False
    failed: Mapping[str, int | None] = field(default_factory=dict)  # node -> exit code
    statistics: Mapping[str, NodeStatistics] = field(default_factory=dict)
    running: Sequence[str] = ()  # nodes that were running when the statistics were asked
    # node -> why its statistics could not be read (`NodeStatistics.from_dict` refused them)
    unreadable: Mapping[str, str] = field(default_factory=dict)
    dropped_reports: int = 0  # state reports the launcher's own hand-off dropped
    not_up: Sequence[str] = ()  # nodes not alive yet when the run ended (before the epoch)
    # what the run was launched with that did not work (a ROS 2 bridge that never reached
    # its router): the run is not the one asked for
    unmet: Sequence[str] = ()


def stall_floor_ms(time_scale: float = 1.0) -> int:
    """The floor of every node's stall threshold, in fleet ms: `STALL_FLOOR_WALL_MS` of wall
    time (scheduling jitter of a loaded machine, which a high ``--time-scale`` multiplies).
    Above it, a node's threshold is twice its shortest timer period (`runtime.core.node_core`)."""
    return math.ceil(STALL_FLOOR_WALL_MS * time_scale)


def statistics_reasons(node: str, stats: NodeStatistics) -> list[str]:
    """Why `node`'s final statistics make a verdict inconclusive (empty: they do not).

    Every `Rejection` reason counts (input the node refused: forged, invalid,
    oversize, of the wrong type), one reason line each.
    """
    reasons = []
    if stats.dropped_overflow:
        reasons.append(f"{node} dropped {stats.dropped_overflow} samples at the transport "
                       "hand-off (its loop fell behind)")
    if stats.gaps:
        reasons.append(f"{node} lost {stats.gaps} samples on reliable topics (sequence gaps)")
    if stats.dropped_lossless:
        reasons.append(f"{node} dropped {stats.dropped_lossless} samples from the KEEP_LAST "
                       "queue of a RELIABLE (lossless) subscription")
    reasons += [f"{node} rejected {count} samples ({reason.counter})"
                for reason, count in stats.rejected.items() if count]
    if stats.stalls:
        reasons.append(f"{node} fell behind its timers by up to {stats.max_lateness_ms} ms "
                       f"({stats.stalls} timers later than its stall threshold of "
                       f"{stats.stall_threshold_ms} ms: it stalled)")
    return reasons


def external_input_line(statistics: Mapping[str, NodeStatistics]) -> str | None:
    """The detail line of a run whose nodes took input from outside the fleet, or None."""
    taken = [f"{node}: {', '.join(came)}" for node, stats in sorted(statistics.items())
             if (came := _came_in(stats))]
    if not taken:
        return None
    return (f"took external input (from outside the fleet; the checked model has no such "
            f"input): {'; '.join(taken)}")


def _came_in(stats: NodeStatistics) -> list[str]:
    """What one node took from outside the fleet, in words."""
    came = [f"{k} on {name} from {source}" for source, name, k in stats.outside_input]
    if stats.external_input and not any(s is Outside.BRIDGE for s, _, _ in stats.outside_input):
        came.append(f"{stats.external_input} samples from {Outside.BRIDGE}")
    if stats.played:
        came.append(f"{stats.played} recorded samples from twinfleet play --into-fleet")
    return came


def _after(report: StateReport | None) -> str:
    return "in the initial states" if report is None else f"after {report.event()}"


@final
class LiveJudge:
    """Judges a scenario's properties on state reports (module docstring).

    Args:
        scenario: the scenario run (its properties and nodes).
        time_scale: the run's time scale (for the stall threshold).
        budget_s: wall seconds one evaluation may take (None: unlimited).
    """

    def __init__(self, scenario: Scenario, *, time_scale: float = 1.0,
                 budget_s: float | None = EVAL_BUDGET_S,
                 say: Callable[[str], None] | None = None) -> None:
        self.budget_s, self.say = budget_s, say
        self.held_at: dict[str, int] = {}  # eventually and within properties: when they held
        self.nodes = [cfg.instantiate() for cfg in scenario.nodes]
        self.names = [n.name for n in self.nodes]
        self.states: dict[str, Any] = {n.name: n.state for n in self.nodes}
        self.stall_ms = stall_floor_ms(time_scale)
        self.failure_name = next((p.name for p in scenario.properties if p.kind == "no_failure"),
                                 "no_failure")
        self.watches = [self._watch(p, scenario.source) for p in scenario.properties
                        if p.kind not in ("no_failure",)]
        self.violations: list[tuple[str, str, tuple[str, ...]]] = []  # property, summary, details
        self.failures: dict[str, int] = {}  # node -> handler failures reported
        self.breaches: dict[str, str] = {}  # node -> its first failure that breaks the contract
        self.errors: list[str] = []
        self.lost: dict[str, int] = {}
        self.reports = 0
        self.strangers = 0  # reports from names that are not nodes of the scenario
        self.undecodable: list[str] = []
        self.now = 0
        self._seq: dict[str, int] = {}
        for w in self.watches:  # as the checker checks the initial world
            if w.cfg.kind == "invariant" and self._evaluate(w, None) is False:
                self._violated(w.cfg.name, f"invariant {w.expr.source!r} is false in the "  # type: ignore[union-attr]
                               "initial states", None, self._read_by(w))

    def _watch(self, p: PropertyConfig, source: str) -> _Watch:
        expr = None if p.expr is None else parse_expression(p.expr, self.names, f"{source}:{p.name}")
        reads = None
        if expr is not None and "nodes" not in expr.names and "now" not in expr.names:
            reads = frozenset(expr.names)
        return _Watch(p, expr, reads)

    def reads(self) -> frozenset[str]:
        """The nodes whose states some property reads (the others report only failures)."""
        exprs = [w for w in self.watches if w.expr is not None]
        if any(w.reads is None for w in exprs):
            return frozenset(self.names)
        return frozenset(n for w in exprs for n in w.reads or ())

    # ------------------------------------------------------------------ reports

    def on_report(self, report: StateReport) -> None:
        """Account for one state report: update the view, evaluate what it may change.
        A report from a name that is not a node of the scenario is ignored (counted)."""
        if report.node not in self.states:
            self.strangers += 1
            return
        self.reports += 1
        last = self._seq.get(report.node, 0)
        if report.seq > last + 1:
            self.lost[report.node] = self.lost.get(report.node, 0) + report.seq - last - 1
        self._seq[report.node] = max(last, report.seq)
        self.now = max(self.now, report.now_ms)  # fleet time: 0 is the launcher's epoch
        if report.failure is not None:
            self.failures[report.node] = self.failures.get(report.node, 0) + 1
            if report.breach:
                self.breaches.setdefault(report.node, f"contract breach in {report.failure}")
            elif not any(v[0] == self.failure_name for v in self.violations):
                self._violated(self.failure_name, f"a handler failed: {report.failure}",
                               report, self.names)
        if report.state is not None:
            try:
                self.states[report.node] = restore(report.state)
            except Exception as exc:  # not a snapshot: the view of this node is lost
                self.undecodable.append(f"{report.node} sent an undecodable state ({exc})")
                return
        for watch in self.watches:
            self._judge(watch, report)

    def _judge(self, w: _Watch, report: StateReport) -> None:
        kind = w.cfg.kind
        if w.expr is None or w.broken is not None or kind not in ("invariant", "eventually",
                                                                  "within"):
            return
        if w.held and kind != "invariant":
            return
        if kind == "within" and w.cfg.within_ms is not None and self.now > w.cfg.within_ms:
            self._violated(w.cfg.name, f"{w.expr.source!r} did not hold within "
                           f"{w.cfg.within_ms} ms (still false at t={self.now} ms)", report,
                           self._read_by(w))
            w.broken = "decided"
            return
        touched = report.state is not None and (w.reads is None or report.node in w.reads)
        if not touched and w.reads is not None:
            return
        value = self._evaluate(w, report)
        if value is None:
            return
        if kind == "invariant" and not value:
            if not any(v[0] == w.cfg.name for v in self.violations):
                self._violated(w.cfg.name, f"invariant {w.expr.source!r} is false at "
                               f"t={self.now} ms", report, self._read_by(w))
        elif kind != "invariant" and value:
            w.held = True
            self.held_at[w.cfg.name] = self.now
            if self.say is not None:
                self.say(f"{w.cfg.name} held at t={self.now} ms")

    def settled(self) -> bool:
        """Whether the run's outcome is settled: it has eventually (or within) properties and
        every one has held; the invariants stay judged until the run ends."""
        goals = [w for w in self.watches if w.cfg.kind in ("eventually", "within")]
        return bool(goals) and all(w.held for w in goals)

    def _evaluate(self, w: _Watch, report: StateReport | None) -> bool | None:
        assert w.expr is not None
        env: dict[str, Any] = {"now": self.now, "nodes": dict(self.states)}
        env.update(self.states)
        try:
            with time_limit(self.budget_s):
                return w.expr.evaluate(env)
        except Overtime:
            w.broken = (f"{w.cfg.name}: evaluating {w.expr.source!r} took longer than "
                        f"{self.budget_s:g} s (at t={self.now} ms); not judged")
        except Exception as exc:
            w.broken = "error"
            self.errors.append(f"property {w.cfg.name!r}: {w.expr.source!r} raised "
                               f"{type(exc).__name__}: {exc} ({_after(report)})")
        return None

    def _read_by(self, w: _Watch) -> Sequence[str]:
        """The nodes whose states a report of `w` shows: those its expression reads (a
        property reading `now` is evaluated on every report, but reads no more nodes)."""
        reads = w.reads if w.reads is not None or w.expr is None else \
            nodes_read(w.expr.source, self.names)
        return self.names if reads is None else [n for n in self.names if n in reads]

    def _states(self, w: _Watch) -> tuple[str, ...]:
        """The states of the nodes `w` reads, as a violation report shows them."""
        return tuple(f"{n}: {repr(self.states[n])[:_STATE_CHARS]}" for n in self._read_by(w))

    def _violated(self, name: str, summary: str, report: StateReport | None,
                  nodes: Sequence[str]) -> None:
        details = [f"at t={self.now} ms, {_after(report)}"]
        details += [f"{n}: {repr(self.states[n])[:_STATE_CHARS]}" for n in nodes]
        self.violations.append((name, f"{name} violated: {summary}", tuple(details)))

    # ------------------------------------------------------------------ the verdict

    def verdict(self, end: RunEnd) -> Verdict:
        """The run's result (`_decide`), with detail lines for input from outside the fleet,
        which neither voids nor decides the verdict: what the nodes took from outside
        (`external_input_line`: said first, as what the run shows was partly not the
        nodes' own doing), and samples an operator's command sent that nodes refused."""
        decided = self._decide(end)
        taken = external_input_line(end.statistics)
        first = (taken,) if taken is not None else ()
        refused = tuple(f"external input: {node} refused {stats.rejected_external} samples "
                        "an operator's command sent (e.g. `twinfleet topic pub --force`)"
                        for node, stats in sorted(end.statistics.items())
                        if stats.rejected_external)
        if not first and not refused:
            return decided
        return dataclasses.replace(decided, details=(*first, *decided.details, *refused))

    def _decide(self, end: RunEnd) -> Verdict:
        """The run's result: a property that raised; a message of a type its handler does
        not take (a contract breach); a failed node process; inconclusive
        reasons (which also void a violation: it may come from the lost samples or the
        stall, not from the code); violations; an interruption; what never held; else holds."""
        if self.errors:
            return Verdict(Status.ERROR, self.errors[0], tuple(self.errors[1:]))
        wrong = [line for _, stats in sorted(end.statistics.items()) for line in stats.wrong_types]
        if wrong:  # the checker stops at such a send: the same breach, in the same words
            return Verdict(Status.BREACH, wrong[0], tuple(wrong[1:]))
        if self.breaches:  # as the checker, no verdict on code that breaks the contract
            first, *others = self.breaches.values()
            return Verdict(Status.BREACH, first, tuple(others))
        if end.failed:  # a process that died is a fact of the run, lost samples or not
            nodes = ", ".join(f"{n} (exit code {c})" for n, c in end.failed.items())
            return Verdict(Status.VIOLATED, f"node failed: {nodes}")
        reasons = self.inconclusive_reasons(end)
        seen = tuple(f"seen, but not conclusive: {v[1]}" for v in self.violations)
        if reasons and (self.violations or not end.interrupted):
            return Verdict(Status.INCONCLUSIVE, reasons[0],
                           tuple(reasons[1:]) + seen + self._unjudged())
        if self.violations:
            name, summary, details = self.violations[0]
            more = tuple(f"also violated: {v[0]}" for v in self.violations[1:])
            return Verdict(Status.VIOLATED, summary, details + more + self._unjudged(), name)
        if end.interrupted:
            return Verdict(Status.INTERRUPTED, end.reason)
        unmet = [w for w in self.watches if w.cfg.kind in ("eventually", "within") and not w.held]
        early = [w for w in unmet if w.cfg.kind == "within" and self.now <= (w.cfg.within_ms or 0)]
        if early:  # neither held nor past its deadline: the run was too short to judge it
            w = early[0]
            return Verdict(Status.INCONCLUSIVE, f"the run ended at t={self.now} ms, before "
                           f"{w.cfg.name}'s within_ms {w.cfg.within_ms} had passed",
                           self._unjudged())
        if unmet:
            w = unmet[0]
            assert w.expr is not None
            return Verdict(Status.VIOLATED, f"{w.cfg.name} violated: {w.expr.source!r} never "
                           f"held before the run ended ({end.reason})",
                           (f"at the end, t={self.now} ms", *self._states(w), *self._unjudged()),
                           w.cfg.name)
        judged = [w.cfg.name for w in self.watches if w.cfg.kind in ("invariant", "eventually",
                                                                    "within")]
        text = ", ".join([*judged, self.failure_name]) + " hold"
        return Verdict(Status.HOLDS, text, self._unjudged())

    def inconclusive_reasons(self, end: RunEnd) -> list[str]:
        """Why the run cannot back a verdict (module docstring); empty when it can."""
        reasons = [w.broken for w in self.watches if w.broken not in (None, "decided", "error")]
        reasons += end.unmet
        if end.not_up:
            reasons.append(f"the run ended before the fleet was up ({end.reason}; not alive "
                           f"yet: {', '.join(end.not_up)}): nothing ran to judge")
        for node in self.names:
            if node in end.statistics:
                reasons += statistics_reasons(node, end.statistics[node])
            elif node in end.unreadable:
                reasons.append(f"{node} sent statistics the launcher cannot read "
                               f"({end.unreadable[node]})")
            elif node in end.running and node not in end.not_up:
                reasons.append(f"{node} did not answer for its statistics")
        reasons += [f"{n} lost {k} state reports" for n, k in sorted(self.lost.items())]
        reasons += self.undecodable[:1]
        if end.dropped_reports:
            reasons.append(f"the launcher dropped {end.dropped_reports} samples at its hand-off "
                           "(state reports and report topics)")
        return [r for r in reasons if r is not None]

    def _unjudged(self) -> tuple[str, ...]:
        skipped = [w.cfg.name for w in self.watches if w.cfg.kind in ("deadlock", "quiescence")]
        if not skipped:
            return ()
        return (f"not judged live: {', '.join(skipped)} (a live run cannot see that no event "
                "is pending anywhere; `twinfleet check` judges it)",)
