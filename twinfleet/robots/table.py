"""The experiment table: one row per scenario, as the paper's Tables 4 and 5 lay it out.

A `Row` holds a scenario's parameters, one `CheckCell` per checker semantics,
a `LiveSummary` of its live runs, the `Prediction` of P(pass) from simulations
under a timing model, and the paper's own figures (`PaperRow`).
`COLUMNS` names every CSV column for a list of semantics; `to_csv` and
`to_markdown` render rows with them. Pure formatting: nothing here runs
anything, so the module imports neither the checker's search nor the live
runtime (only the checker's arithmetic on counts, `checker.estimate`).
"""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import final

from twinfleet.robots.paper import PaperRow
from twinfleet.runtime.contract.kinds import Status


@final
@dataclass(frozen=True, slots=True)
class CheckCell:
    """One checker run of a scenario under one semantics.

    Attributes:
        semantics: the checker semantics (a `checker.semantics.Semantics` value).
        status: the checker's `Status`: holds, violated or unknown.
        detail: the violated property, or why there is no answer.
        states: distinct states.
        transitions: transitions (handler runs, revisits included).
        rmc_transitions: transitions counted as RMC does (+ one per initial state).
        time_s: wall time of the search.
        trace: where the counterexample was written, if any.
    """

    semantics: str
    status: Status
    detail: str
    states: int
    transitions: int
    rmc_transitions: int
    time_s: float
    trace: str | None = None

    def __post_init__(self) -> None:
        # A cell read back from a CSV or JSON file carries the status's text.
        object.__setattr__(self, "status", Status(self.status))

    @property
    def result(self) -> str:
        """The paper's wording: "satisfied", "violated: <property>", "unknown: <why>"."""
        if self.status is Status.HOLDS:
            return "satisfied"
        if self.status is Status.VIOLATED:
            return f"violated: {self.detail}"
        return f"unknown: {self.detail}"


@final
@dataclass(slots=True)
class LiveSummary:
    """Counts over a scenario's live runs.

    Attributes:
        planned: runs asked for.
        time_scale: fleet time per wall time.
        passed: runs with every robot arrived and no collision.
        collision_runs: runs in which the map server reported a collision.
        unarrived_runs: runs without a collision that ended with some robot not arrived
            (stuck, or out of time); a run with a collision counts as a collision only.
        node_failure_runs: runs in which a node process failed.
        wall_s: wall seconds of every run.
    """

    planned: int
    time_scale: float
    passed: int = 0
    collision_runs: int = 0
    unarrived_runs: int = 0
    node_failure_runs: int = 0
    wall_s: list[float] = field(default_factory=list)

    @property
    def runs(self) -> int:
        """Runs completed."""
        return len(self.wall_s)

    @property
    def failed(self) -> int:
        """Runs that did not pass."""
        return self.runs - self.passed

    def add(self, *, passed: bool, collision: bool, all_arrived: bool, node_failed: bool,
            wall_s: float) -> None:
        """Count one finished run."""
        self.passed += passed
        self.collision_runs += collision
        self.unarrived_runs += not all_arrived and not collision
        self.node_failure_runs += node_failed
        self.wall_s.append(wall_s)

    @property
    def simulations(self) -> str:
        """ "k/N passed, m/N failed", with N the runs completed (and a note if interrupted)."""
        n = self.runs
        text = f"{self.passed}/{n} passed, {self.failed}/{n} failed"
        if n < self.planned:
            text += f" (stopped after {n} of {self.planned})"
        return text

    @property
    def failures(self) -> str:
        """Why runs failed: "collision 3, not arrived 1", or "-"."""
        parts = [f"{label} {count}" for label, count in (
            ("collision", self.collision_runs), ("not arrived", self.unarrived_runs),
            ("node failure", self.node_failure_runs)) if count]
        return ", ".join(parts) or "-"


@final
@dataclass(frozen=True, slots=True)
class Prediction:
    """How likely a live run of a case is to pass, as the simulations estimate it.

    Attributes:
        passes: simulations that violated no property.
        simulations: simulations run.
        low, high: the Clopper–Pearson interval of P(pass) at `confidence`.
        confidence: the interval's confidence.
        time_s: wall seconds the simulations took.
        trace: a violating simulation written as a trace, if any.
    """

    passes: int
    simulations: int
    low: float
    high: float
    confidence: float
    time_s: float
    trace: str | None = None

    @property
    def p(self) -> float:
        """The point estimate of P(pass)."""
        return self.passes / self.simulations if self.simulations else 0.0

    @property
    def text(self) -> str:
        """ "0.62 [0.49, 0.74]" """
        return f"{self.p:.2f} [{self.low:.2f}, {self.high:.2f}]"

    def agreement_p(self, passed: int, runs: int) -> float:
        """The p-value of `passed` live passes in `runs` against this prediction."""
        # imported here: `twinfleet --help` reads this module and loads none of the checker
        from twinfleet.checker.estimate import agreement_p_value

        return agreement_p_value(passed, runs, self.low, self.high, self.confidence)


@final
@dataclass(slots=True)
class Row:
    """One scenario of the experiment.

    Attributes:
        case: scenario name (`c1a`, `c2a_rebeca`, `headon`).
        scenario: the scenario file as given.
        profile: robot profile of the file.
        scan_ms: the map server's scan period.
        robots: per robot (name, speed m/s, max wait ms).
        checks: checker result per semantics, in the order run.
        live: the live runs, or None when none were run.
        prediction: P(pass) from simulations, or None when none were run.
        paper: the paper's figures for this case, if it is one of the paper's.
    """

    case: str
    scenario: str
    profile: str
    scan_ms: int | None
    robots: tuple[tuple[str, float, int], ...]
    checks: dict[str, CheckCell] = field(default_factory=dict)
    live: LiveSummary | None = None
    paper: PaperRow | None = None
    prediction: Prediction | None = None

    @property
    def parameters(self) -> str:
        """Per robot "speed/max wait" as the paper's tables give them: ".5/1500 .7/2000 …"."""
        return " ".join(f"{_speed(v)}/{w}" for _, v, w in self.robots)

    def reference_check(self) -> CheckCell | None:
        """The verdict live runs are compared with: `ros` (Zenoh's per-sender FIFO) if run."""
        return self.checks.get("ros") or next(iter(self.checks.values()), None)

    @property
    def agreement(self) -> str:
        """How the live runs relate to the checker's verdict (see `docs/experiment.md`)."""
        check, live = self.reference_check(), self.live
        if check is None or live is None or live.runs == 0:
            return "-"
        seen = live.collision_runs
        if check.status is Status.UNKNOWN:
            return f"no verdict; live collisions in {seen}/{live.runs}"
        if check.status is Status.HOLDS:
            if seen:
                return f"CONTRADICTION: live collision in {seen}/{live.runs}, checker says none"
            if live.unarrived_runs:
                return (f"CONTRADICTION?: {live.unarrived_runs}/{live.runs} runs did not finish, "
                        "checker says all arrive")
            return "agree: no collision"
        if check.detail == "no_collision":
            if seen:
                return f"agree: collision live in {seen}/{live.runs}"
            return f"collision not seen live (0/{live.runs}); see trace"
        return f"checker: {check.detail} violated; live failed {live.failed}/{live.runs}"

    @property
    def agreement_p(self) -> float | None:
        """The p-value of the live passes against the prediction (None: one is missing)."""
        if self.prediction is None or self.live is None or self.live.runs == 0:
            return None
        return self.prediction.agreement_p(self.live.passed, self.live.runs)

    @property
    def contradiction(self) -> bool:
        """True when a live run did what the checker proved impossible."""
        return self.agreement.startswith("CONTRADICTION")


def _speed(v: float) -> str:
    text = f"{v:g}"
    return text[1:] if text.startswith("0.") else text


def _int(n: int | None) -> str:
    return "" if n is None else f"{n:,}"


def columns(semantics: Sequence[str]) -> list[str]:
    """CSV column names for the semantics run, in order."""
    cols = ["case", "scenario", "profile", "scan_ms", "parameters"]
    for sem in semantics:
        cols += [f"{sem}_result", f"{sem}_states", f"{sem}_transitions",
                 f"{sem}_rmc_transitions", f"{sem}_time_s", f"{sem}_trace"]
    cols += ["predicted_pass", "predicted_low", "predicted_high", "predicted_simulations",
             "agreement_p", "runs", "passed", "failed", "collision_runs", "unarrived_runs", "time_scale",
             "simulations", "agreement", "paper_result", "paper_states", "paper_transitions",
             "paper_simulations"]
    return cols


def csv_record(row: Row, semantics: Sequence[str]) -> dict[str, object]:
    """One CSV record (raw values) for `row`."""
    rec: dict[str, object] = {"case": row.case, "scenario": row.scenario, "profile": row.profile,
                              "scan_ms": row.scan_ms, "parameters": row.parameters}
    for sem in semantics:
        c = row.checks.get(sem)
        rec.update({f"{sem}_result": c.result if c else "", f"{sem}_states": c.states if c else "",
                    f"{sem}_transitions": c.transitions if c else "",
                    f"{sem}_rmc_transitions": c.rmc_transitions if c else "",
                    f"{sem}_time_s": f"{c.time_s:.2f}" if c else "",
                    f"{sem}_trace": (c.trace or "") if c else ""})
    live, pred, agree = row.live, row.prediction, row.agreement_p
    rec.update({"predicted_pass": f"{pred.p:.4f}" if pred else "",
                "predicted_low": f"{pred.low:.4f}" if pred else "",
                "predicted_high": f"{pred.high:.4f}" if pred else "",
                "predicted_simulations": pred.simulations if pred else "",
                "agreement_p": "" if agree is None else f"{agree:.4g}"})
    rec.update({"runs": live.runs if live else 0, "passed": live.passed if live else 0,
                "failed": live.failed if live else 0,
                "collision_runs": live.collision_runs if live else 0,
                "unarrived_runs": live.unarrived_runs if live else 0,
                "time_scale": f"{live.time_scale:g}" if live else "",
                "simulations": live.simulations if live else "",
                "agreement": row.agreement})
    p = row.paper
    rec.update({"paper_result": p.result if p else "", "paper_states": p.states if p else "",
                "paper_transitions": p.transitions if p else "",
                "paper_simulations": p.simulations if p else ""})
    return rec


def to_csv(rows: Sequence[Row], semantics: Sequence[str]) -> str:
    """The rows as CSV text with a header line (`columns(semantics)`)."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=columns(semantics), lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow(csv_record(row, semantics))
    return buf.getvalue()


def markdown_header(semantics: Sequence[str]) -> list[str]:
    """The Markdown column titles."""
    head = ["case", "scan ms", "speed m/s / max wait ms (r1, r2, …)"]
    for sem in semantics:
        head += [f"{sem}: result", f"{sem}: states", f"{sem}: transitions / RMC-style"]
    return head + ["predicted P(pass) [interval]", "simulations", "agreement p",
                   "live failures", "agreement", "paper: result",
                   "paper: states / transitions", "paper: simulations"]


def markdown_cells(row: Row, semantics: Sequence[str]) -> list[str]:
    """The Markdown cells of one row (same order as `markdown_header`)."""
    cells = [row.case, "" if row.scan_ms is None else str(row.scan_ms), row.parameters]
    for sem in semantics:
        c = row.checks.get(sem)
        if c is None:
            cells += ["", "", ""]
        else:
            cells += [c.result, _int(c.states), f"{_int(c.transitions)} / {_int(c.rmc_transitions)}"]
    live, p, pred, agree = row.live, row.paper, row.prediction, row.agreement_p
    cells += [f"{pred.text} ({pred.simulations} sim.)" if pred else "",
              live.simulations if live else "", "" if agree is None else f"{agree:.3g}",
              live.failures if live else "", row.agreement]
    if p is None:
        cells += ["", "", ""]
    else:
        cells += [p.result, f"{_int(p.states)} / {_int(p.transitions)}", p.simulations]
    return cells


def to_markdown(rows: Sequence[Row], semantics: Sequence[str]) -> str:
    """The rows as a GitHub Markdown table."""
    head = markdown_header(semantics)
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    for row in rows:
        cells = [c.replace("|", "\\|") for c in markdown_cells(row, semantics)]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
