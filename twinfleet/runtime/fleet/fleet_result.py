"""How a run of the fleet ended: `EndReason`, `FleetResult`, its summary lines and its
run-record summary."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import Enum, unique
from typing import Any, final

from twinfleet.runtime.access.connection import EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK
from twinfleet.runtime.contract.kinds import EXIT_INCONCLUSIVE, EXIT_TERMINATED, Status
from twinfleet.runtime.core.statistics import NodeStatistics
from twinfleet.runtime.fleet.live_verdict import RESULT_WORDS, Verdict
from twinfleet.runtime.fleet.run_record import RunRecord


@unique
class EndReason(Enum):
    """What ended a run; `RunEnding.detail` says it in words for people."""

    NOT_UP = "not up"  # some node was not alive within the start-up limit
    TIMEOUT = "timeout"  # `live.timeout_s` passed
    INTERRUPTED = "interrupted"  # SIGINT reached the launcher (Ctrl-C)
    TERMINATED = "terminated"  # SIGTERM reached the launcher (a stop request)
    SHUTDOWN = "shutdown"  # a message on the fleet's shutdown topic asked for it
    NODE_FAILED = "node failed"  # a node process exited with an error code
    NODE_KILLED = "node killed"  # a node process died of a signal the launcher did not send
    ALL_EXITED = "all exited"  # every node process ended by itself
    SETTLED = "settled"  # every `eventually` property held (``until_settled``)
    VIOLATION = "violation"  # a property was violated (``until_violation``)
    REPORT_FINISHED = "report finished"  # the scenario's run report says it is over
    DRIVER = "driver"  # the launch driver (a test, the live replay, ...) returned or failed


@final
@dataclass(frozen=True, slots=True)
class RunEnding:
    """Why a run ended: what ended it, and the detail in words ("timeout after 5 s")."""

    kind: EndReason
    detail: str

    @classmethod
    def node_exit(cls, node: str, code: int) -> RunEnding:
        """A node process that ended with `code` (negative: killed by that signal)."""
        kind = EndReason.NODE_KILLED if code < 0 else EndReason.NODE_FAILED
        return cls(kind, f"node {node} failed (exit code {code})")


@dataclass(frozen=True)
class FleetResult:
    """How a run ended.

    Attributes:
        fleet: the fleet name (Zenoh key prefix `twinfleet/<fleet>`).
        endpoint: the router endpoint the nodes connected to.
        reason: why the run ended, in words ("timeout after 5 s", "shutdown requested by ...").
        end: what ended it (`EndReason`): what code reads, never `reason`.
        exit_codes: last exit code of every node (negative: killed by that signal).
        failed: nodes that failed (non-zero exit, or had to be killed).
        restarts: respawn count per node.
        last_messages: last message seen on each `live.summary_topics` topic.
        duration_s: wall time of the run.
        report: the scenario's run report (`live.report`), if any.
        verdict: the live verdict on the scenario's properties (None: not monitored).
        handler_failures: handler failures per node, from the state reports.
        statistics: each node's counters at the end (when the launcher read them).
    """

    fleet: str
    endpoint: str
    reason: str
    end: EndReason
    exit_codes: Mapping[str, int | None]
    failed: tuple[str, ...]
    restarts: Mapping[str, int] = field(default_factory=dict)
    last_messages: Mapping[str, Any] = field(default_factory=dict)
    duration_s: float = 0.0
    report: Any = None
    verdict: Verdict | None = None
    handler_failures: Mapping[str, int] = field(default_factory=dict)
    state_reports: int = 0  # state reports the monitor received
    statistics: Mapping[str, NodeStatistics] = field(default_factory=dict)  # at the end

    @property
    def ok(self) -> bool:
        """True when no node failed."""
        return not self.failed

    @property
    def passed(self) -> bool:
        """True when no node failed and the live verdict (`runtime.fleet.live_verdict`) holds;
        without one (``judge=False``), when the scenario's report (if any) says so."""
        if self.verdict is not None:
            return self.ok and self.verdict.status is Status.HOLDS
        return self.ok and (self.report is None or self.report.passed())

    @property
    def interrupted(self) -> bool:
        """True when the run ended on SIGINT or SIGTERM (Ctrl-C, a stop request)."""
        return self.end in _SIGNAL_EXITS

    @property
    def exit_code(self) -> int:
        """0 passed, 1 violated or a node failed, 2 a property raised, 3 inconclusive,
        130 interrupted (Ctrl-C), 143 terminated (SIGTERM)."""
        code = self.verdict.exit_code if self.verdict is not None else (
            EXIT_INTERRUPTED if self.interrupted else EXIT_OK if self.passed else EXIT_FAILED)
        if code == EXIT_INTERRUPTED:
            return signal_exit_code(self.end) or code  # SIGTERM: 143, as everywhere
        return code


_OUTCOMES = ((EXIT_OK, "passed"), (EXIT_FAILED, "failed"), (EXIT_INCONCLUSIVE, "inconclusive"))


def runs_summary(name: str, codes: list[int], runs: int) -> str:
    """The line after ``launch --runs N``: how many runs passed, failed (a property
    violated) and were inconclusive, each said; another end (interrupted, an error) too."""
    counts = [(sum(c == code for c in codes), what) for code, what in _OUTCOMES]
    counts += [(sum(c not in dict(_OUTCOMES) for c in codes), "ended otherwise"),
               (runs - len(codes), "not run")]
    words = [f"{n}/{runs} {what}" for i, (n, what) in enumerate(counts) if n or i < 2]
    return f"{name}: {', '.join(words)}"


_SIGNAL_EXITS = {EndReason.INTERRUPTED: EXIT_INTERRUPTED, EndReason.TERMINATED: EXIT_TERMINATED}


def signal_exit_code(end: EndReason | None) -> int | None:
    """130 for a run ended by SIGINT (Ctrl-C), 143 (128 + 15) by SIGTERM, as every command
    exits on them; None for a run that ended otherwise."""
    return _SIGNAL_EXITS.get(end) if end is not None else None


def format_result(result: FleetResult) -> list[str]:
    """Human-readable summary lines of a run."""
    lines = [f"run ended after {result.duration_s:.1f} s: {result.reason}"]
    for name, code in result.exit_codes.items():
        failures = result.handler_failures.get(name, 0)
        status = "FAILED" if name in result.failed else (
            f"FAILED: {failures} handler failures" if failures else "ok")
        extra = f", restarts {result.restarts[name]}" if result.restarts.get(name) else ""
        stats = result.statistics.get(name)
        counters = f"  {stats.nonzero()}" if stats is not None else ""
        lines.append(f"  {name}: exit code {code} ({status}{extra}){counters}")
    for topic, msg in result.last_messages.items():
        lines.append(f"  last on {topic}: {msg}")
    if result.report is not None:
        lines += result.report.render().splitlines()
        if result.verdict is None:
            status = Status.HOLDS if result.passed else Status.VIOLATED
            lines.append(f"result: {RESULT_WORDS[status]}")
    if result.verdict is not None:
        lines += result.verdict.lines()
    return lines


def record_summary(record: RunRecord, result: FleetResult) -> None:
    """The run record's ``summary`` line (`runtime.fleet.run_record`)."""
    report = None
    if result.report is not None:
        report = {"passed": result.report.passed(), "text": result.report.render(),
                  "data": result.report}
    verdict = None
    if result.verdict is not None:
        v = result.verdict
        verdict = {"status": v.status, "summary": v.summary, "details": list(v.details),
                   "property": v.property_name, "exit_code": v.exit_code}
    record.write("summary", ok=result.ok, passed=result.passed, verdict=verdict,
                 reason=result.reason, end=result.end.value,
                 exit_codes=result.exit_codes, failed=result.failed, restarts=result.restarts,
                 duration_s=round(result.duration_s, 3), last_messages=result.last_messages,
                 report=report)
