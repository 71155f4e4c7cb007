"""The paper's experiment end to end: checker verdicts and live runs, one table.

For each scenario `run_experiment` runs the checker once per semantics
(counterexample traces under `OUT/traces/`), predicts P(a live run passes)
from simulations under a timing model (`robots.prediction`), then N live runs one after
another in this process (seeds S, S+1, …; the nodes' output goes to
`OUT/logs/<case>.live.log`; the fleets run a copy of the scenario file in
`OUT/scenarios/`, see `robots.live.private_copy`), and fills one
`robots.table.Row`. The table
is written as `experiment.md`, `experiment.csv` and `experiment.json` (every
run's arrival times and collisions too) after every scenario and once more at
the end, also when Ctrl-C stopped the experiment: what was done is kept, a
half-done scenario shows "stopped after k of N". A finished scenario is
kept in `OUT/cases/` (`robots.resume`): the same command run again skips it.

Live runs end as soon as their outcome is known (`robots.live`), or after
`startup_s + horizon_s / time_scale` wall seconds: `horizon_s` fleet seconds
is far beyond any arrival of the paper's cases (the slowest robot of C1a
arrives after about 50 s).
"""

from __future__ import annotations

import asyncio
import json
import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO, final

from twinfleet.checker.driver import CheckOptions, check
from twinfleet.checker.options import Semantics
from twinfleet.checker.outcome import SearchStatistics
from twinfleet.robots import DEFAULT_TIME_SCALE
from twinfleet.robots.live import LiveRunResult, live_run, private_copy
from twinfleet.robots.paper import paper_row
from twinfleet.robots.resume import FinishedCase, fingerprint, load_case, save_case
from twinfleet.robots.table import CheckCell, LiveSummary, Row, csv_record, to_csv, to_markdown
from twinfleet.robots.timing import (
    arrival_errors,
    predicted_arrivals,
    robot_names,
    robot_profile,
    summarise,
)
from twinfleet.runtime.fleet.fleet_result import EndReason
from twinfleet.runtime.scenario.overrides import load_with_params
from twinfleet.runtime.scenario.spec import Scenario, ScenarioError

SEMANTICS = (Semantics.ROS, Semantics.REBECA)
_CHECK_PROGRESS_S = 5.0
_RETRIES = 2  # re-runs of a run whose node was killed by a signal from outside the fleet


@final
@dataclass(frozen=True)
class ExperimentOptions:
    """How to run the experiment.

    Attributes:
        runs: live runs per scenario (0: checker only).
        time_scale: fleet ms per wall ms in live runs.
        semantics: checker semantics to run, in order.
        out: output directory.
        seed: seed of the first live run (default: the scenario's), then +1 per run.
        max_states, max_time_s: checker limits (None: the scenario's `check:` block).
        horizon_s: fleet seconds a live run may last before it counts as not arrived.
        startup_s: wall seconds allowed for starting and stopping the processes.
        stop_on_collision: end a live run at its first collision.
        predict: simulations for the predicted P(pass) (0: no prediction).
        timing: the timing model file of the prediction (None: the loopback model shipped).
        confidence: confidence of the predicted interval.
        workers: local processes for the prediction's simulations.
        params: parameter overrides (``r1.speed:=0.4``) for every scenario: written into a
            copy of it under out/scenarios/with-params, which every check, the prediction
            and every live run then read, so all of them run the same values.
    """

    runs: int = 20
    time_scale: float = DEFAULT_TIME_SCALE
    semantics: tuple[str, ...] = SEMANTICS
    out: Path = Path("out/experiment")
    seed: int | None = None
    max_states: int | None = None
    max_time_s: float | None = None
    horizon_s: float = 180.0
    startup_s: float = 20.0
    stop_on_collision: bool = True
    predict: int = 100
    timing: str | None = None
    confidence: float = 0.99
    workers: int = 1
    params: tuple[str, ...] = ()  # parameter overrides of every scenario, as `check` takes them

    def decisive(self) -> dict[str, Any]:
        """The options that change a case's checks and live runs (what a kept case must
        match to be kept)."""
        return {"runs": self.runs, "time_scale": self.time_scale,
                "semantics": list(self.semantics), "seed": self.seed,
                "max_states": self.max_states, "max_time_s": self.max_time_s,
                "horizon_s": self.horizon_s, "stop_on_collision": self.stop_on_collision,
                **({"params": list(self.params)} if self.params else {})}

    def predictive(self) -> dict[str, Any]:
        """The options that change a case's prediction besides: the timing model's
        content, the simulations, the confidence (a kept case whose prediction differs
        keeps its live runs and is predicted again)."""
        timing = None if self.timing is None else Path(self.timing).read_text()
        return {**self.decisive(), "predict": self.predict, "timing": timing,
                "confidence": self.confidence}

    @property
    def run_timeout_s(self) -> float:
        """Wall seconds after which a live run is ended."""
        return self.startup_s + self.horizon_s / self.time_scale


@final
@dataclass
class Experiment:
    """What was done: rows, every live run, and whether Ctrl-C cut it short."""

    options: ExperimentOptions
    command: str = ""
    rows: list[Row] = field(default_factory=list)
    runs: dict[str, list[LiveRunResult]] = field(default_factory=dict)
    predictions: dict[str, dict[str, int | None]] = field(default_factory=dict)
    retried: list[tuple[str, int, str]] = field(default_factory=list)
    interrupted: bool = False
    stopped_by: EndReason | None = None  # the signal that stopped it (a live run's, or Ctrl-C)
    started: float = field(default_factory=time.time)

    @property
    def contradictions(self) -> list[Row]:
        """Rows whose live runs did what the checker says cannot happen."""
        return [r for r in self.rows if r.contradiction]


class _Interrupted(Exception):
    def __init__(self, end: EndReason) -> None:
        super().__init__(end.value)
        self.end = end


def stderr_progress(text: str) -> None:
    """The default progress sink: one line on stderr."""
    print(f"[experiment] {text}", file=sys.stderr, flush=True)


def load_experiment_scenario(path: str | Path, params: Sequence[str] = ()) -> Scenario:
    """Load a scenario (with parameter overrides `params`) and insist it is a robot fleet
    (a map server with robots)."""
    scenario = load_with_params(path, params)
    if not robot_names(scenario):
        raise ScenarioError(f"{path}: nodes: the experiment needs a map server node with a "
                            "`robots` list (a robot fleet); this scenario has none")
    return scenario


def scenario_row(path: str | Path, scenario: Scenario) -> Row:
    """A row with the scenario's parameters and the paper's figures, nothing run yet."""
    robots = robot_names(scenario)
    scan = None
    params = []
    for cfg in scenario.nodes:
        if hasattr(cfg.params, "robots"):
            scan = getattr(cfg.params, "scan_rate_ms", None)
        elif cfg.name in robots:
            params.append((cfg.name, float(cfg.params.speed), int(cfg.params.max_wait_ms)))
    return Row(case=scenario.name, scenario=str(path), profile=robot_profile(scenario), scan_ms=scan,
               robots=tuple(params), paper=paper_row(scenario.name))


def run_experiment(paths: Sequence[str | Path], options: ExperimentOptions, *,
                   progress: Callable[[str], None] = stderr_progress,
                   command: str = "") -> Experiment:
    """Run the checker and the live runs for every scenario; write the outputs.

    Raises:
        ScenarioError: a scenario is invalid (raised before anything runs).
    """
    scenarios = [_with_params(p, load_experiment_scenario(p, options.params), options)
                 for p in paths]
    exp = Experiment(options, command)
    out = options.out
    (out / "logs").mkdir(parents=True, exist_ok=True)
    try:
        decisive, predictive = options.decisive(), options.predictive()
        for path, scenario in scenarios:
            assert scenario.path is not None  # loaded from a file
            key = fingerprint(scenario.path, decisive)
            predicted = fingerprint(scenario.path, predictive)
            kept = load_case(out, scenario.name, key)
            if kept is not None:
                _take_kept(exp, kept)
                if kept.prediction_key != predicted:
                    progress(f"{scenario.name}: checks and live runs kept ({out / 'cases'}); "
                             "the prediction's options changed: predicting again")
                    _predict(exp, kept.row, path, progress)
                    _keep(exp, kept.row, key, predicted)
                else:
                    progress(f"{scenario.name}: finished by an earlier run with the same "
                             f"options, kept ({out / 'cases'})")
                continue
            row = scenario_row(path, scenario)
            exp.rows.append(row)
            _checks(exp, row, path, progress)
            _predict(exp, row, path, progress)
            _live(exp, row, path, scenario, progress)
            _keep(exp, row, key, predicted)
    except (KeyboardInterrupt, _Interrupted) as exc:
        exp.interrupted = True
        exp.stopped_by = exc.end if isinstance(exc, _Interrupted) else EndReason.INTERRUPTED
        progress("interrupted: writing what was done")
    write_outputs(exp)
    return exp


def _with_params(path: str | Path, scenario: Scenario,
                 options: ExperimentOptions) -> tuple[str | Path, Scenario]:
    """The scenario every part of a case reads: a copy with the overrides written in."""
    if not options.params:
        return path, scenario
    copy = private_copy(scenario, options.out / "scenarios" / "with-params", options.params)
    assert copy.path is not None
    return copy.path, copy


def _keep(exp: Experiment, row: Row, key: str, predicted: str) -> None:
    """Keep a finished case under its fingerprints; rewrite the outputs."""
    save_case(exp.options.out, key, FinishedCase(
        row, exp.runs.get(row.case, []), exp.predictions.get(row.case, {}),
        [r for r in exp.retried if r[0] == row.case], predicted))
    write_outputs(exp)


def _take_kept(exp: Experiment, kept: FinishedCase) -> None:
    case = kept.row.case
    exp.rows.append(kept.row)
    if kept.runs or kept.row.live is not None:
        exp.runs[case] = kept.runs
        exp.predictions[case] = kept.predicted_arrival_ms
    exp.retried += kept.retried


def _predict(exp: Experiment, row: Row, path: str | Path,
             progress: Callable[[str], None]) -> None:
    from twinfleet.robots.prediction import predict

    opts = exp.options
    if opts.predict <= 0:
        return
    progress(f"{row.case}: predicting P(pass) from {opts.predict} simulations "
             f"(time scale {opts.time_scale:g}, {opts.workers} worker(s))")
    row.prediction = pred = predict(
        path, timing=opts.timing, time_scale=opts.time_scale, simulations=opts.predict,
        seed=opts.seed, horizon_s=opts.horizon_s, confidence=opts.confidence,
        workers=opts.workers, out=opts.out)
    progress(f"{row.case}: predicted P(pass) {pred.text} at {pred.confidence:.0%} "
             f"({pred.passes}/{pred.simulations} simulations passed, {pred.time_s:.1f} s)")


def _checks(exp: Experiment, row: Row, path: str | Path, progress: Callable[[str], None]) -> None:
    opts = exp.options
    for sem in opts.semantics:
        progress(f"{row.case}: checking (semantics {sem})")
        trace = opts.out / "traces" / f"{row.case}.{sem}.trace.json"
        last = [time.monotonic()]

        def report(stats: SearchStatistics, sem: str = sem, last: list[float] = last) -> None:
            if time.monotonic() - last[0] >= _CHECK_PROGRESS_S:
                last[0] = time.monotonic()
                progress(f"{row.case} {sem}: {stats.states:,} states, {stats.transitions:,} "
                         f"transitions, {stats.states_per_s:,.0f} states/s, depth {stats.depth}")

        result = check(path, CheckOptions(semantics=Semantics(sem), max_states=opts.max_states,
                                          max_time_s=opts.max_time_s, trace_out=str(trace),
                                          progress=report))
        s = result.statistics
        detail = (result.violation.property if result.violation is not None else result.reason)
        cell = CheckCell(sem, result.status, detail, s.states, s.transitions,
                         result.rmc_transitions, s.elapsed_s, result.trace_path)
        row.checks[sem] = cell
        progress(f"{row.case} {sem}: {cell.result}, {s.states:,} states, {s.transitions:,} "
                 f"transitions (RMC-style {result.rmc_transitions:,}) in {s.elapsed_s:.1f} s"
                 + (f"; trace {result.trace_path}" if result.trace_path else ""))
        if result.interrupted:
            raise _Interrupted(EndReason.INTERRUPTED)  # the checker stops on Ctrl-C


def _live(exp: Experiment, row: Row, path: str | Path, scenario: Scenario,
          progress: Callable[[str], None]) -> None:
    opts = exp.options
    if opts.runs <= 0:
        return
    row.live = summary = LiveSummary(opts.runs, opts.time_scale)
    records = exp.runs.setdefault(row.case, [])
    sem = Semantics.ROS if Semantics.ROS in opts.semantics else (opts.semantics[0] if opts.semantics else None)
    prediction = predicted_arrivals(path, semantics=sem)
    exp.predictions[row.case] = dict(prediction.arrival_ms)
    base = opts.seed if opts.seed is not None else scenario.seed
    scenario = private_copy(scenario, opts.out / "scenarios")
    log_path = opts.out / "logs" / f"{row.case}.live.log"
    with log_path.open("w") as log:
        for k in range(opts.runs):
            seed = base + k
            _header(log, f"run {k + 1}/{opts.runs} of {row.case} (seed {seed}, "
                         f"time scale {opts.time_scale:g})")
            attempt = 0
            while True:  # a run killed from outside the fleet, up to _RETRIES times again
                record = asyncio.run(live_run(scenario, time_scale=opts.time_scale, seed=seed,
                                              timeout_s=opts.run_timeout_s, out=log,
                                              stop_on_collision=opts.stop_on_collision))
                if record.interrupted:
                    raise _Interrupted(EndReason.TERMINATED if record.terminated
                                       else EndReason.INTERRUPTED)
                if not record.killed_from_outside or attempt == _RETRIES:
                    break
                attempt += 1
                exp.retried.append((row.case, seed, record.reason))
                progress(f"{row.case} live {k + 1}/{opts.runs} (seed {seed}): {record.reason}; "
                         "killed from outside the fleet, running it again")
                _header(log, f"run {k + 1}/{opts.runs} of {row.case} again (seed {seed})")
            records.append(record)
            summary.add(passed=record.passed, collision=bool(record.collisions),
                        all_arrived=record.all_arrived, node_failed=bool(record.failed_nodes),
                        wall_s=record.wall_s)
            progress(f"{row.case} live {k + 1}/{opts.runs} (seed {seed}): {record.verdict} "
                     f"[{record.wall_s:.1f} s]")
    agree = row.agreement_p
    progress(f"{row.case}: simulations {summary.simulations}; {row.agreement}"
             + ("" if agree is None else f"; agreement p {agree:.3g}"))


def _header(log: TextIO, text: str) -> None:
    log.write(f"===== {text} =====\n")
    log.flush()


def write_outputs(exp: Experiment) -> list[Path]:
    """Write experiment.md, .csv and .json into the output directory; return their paths."""
    out = exp.options.out
    out.mkdir(parents=True, exist_ok=True)
    sems = exp.options.semantics
    paths = [out / "experiment.md", out / "experiment.csv", out / "experiment.json"]
    paths[0].write_text(markdown_report(exp))
    paths[1].write_text(to_csv(exp.rows, sems))
    paths[2].write_text(json.dumps(json_report(exp), indent=1) + "\n")
    return paths


def markdown_report(exp: Experiment) -> str:
    """The Markdown file: how it was produced, the table, and the failed live runs."""
    o = exp.options
    lines = ["# twinfleet experiment", ""]
    if exp.command:
        lines += ["Produced by:", "", "```", exp.command, "```", ""]
    lines += [f"Live runs: {o.runs} per scenario at time scale {o.time_scale:g} "
              f"(seeds from {'the scenario seed' if o.seed is None else o.seed}); checker "
              f"semantics: {', '.join(o.semantics)}; started "
              f"{time.strftime('%Y-%m-%d %H:%M', time.localtime(exp.started))}."]
    if o.predict > 0:
        lines += ["", f"Predicted P(pass): {o.predict} simulations per case (`ros` rules) under "
                  f"the timing model `{o.timing or 'loopback (shipped)'}` stretched to time scale "
                  f"{o.time_scale:g} (`{o.out / 'timing.yaml'}`), {o.confidence:.0%} "
                  "Clopper-Pearson interval. Agreement p: the exact two-sided binomial p-value "
                  "of the live passes, maximised over the predicted interval, plus "
                  f"{1 - o.confidence:.2g} for the interval's own error (1 when k/N lies in "
                  "the interval; small means model and fleet disagree)."]
    if exp.interrupted:
        lines += ["", "**Interrupted (Ctrl-C): the table shows what was done.**"]
    lines += ["", to_markdown(exp.rows, o.semantics)]
    failures = failed_runs(exp)
    if failures:
        lines += ["Failed live runs (fleet time of the first collision, launcher epoch):", ""]
        lines += [f"- {line}" for line in failures]
        lines.append("")
    if exp.retried:
        lines += ["Runs repeated because a node was killed from outside the fleet:", ""]
        lines += [f"- {case} seed {seed}: {why}" for case, seed, why in exp.retried]
        lines.append("")
    traces = [(row.case, c) for row in exp.rows for c in row.checks.values() if c.trace]
    if traces:
        lines += ["Counterexample traces (`twinfleet replay T`, `twinfleet render T -o x.png`):", ""]
        lines += [f"- {case} ({c.semantics}): `{c.trace}`" for case, c in traces]
        lines.append("")
    drawn = [(row.case, row.prediction.trace) for row in exp.rows
             if row.prediction is not None and row.prediction.trace]
    if drawn:
        lines += ["A failing simulation of each prediction (`twinfleet replay T [--live]`):", ""]
        lines += [f"- {case}: `{trace}`" for case, trace in drawn]
        lines.append("")
    return "\n".join(lines)


def failed_runs(exp: Experiment) -> list[str]:
    """One line per case and kind of failure: seeds, and the time range of collisions."""
    lines = []
    for case, records in exp.runs.items():
        groups: dict[str, list[LiveRunResult]] = {}
        for r in records:
            if not r.passed:
                key = (f"collision {r.collisions[0][0]}-{r.collisions[0][1]}" if r.collisions
                       else r.verdict)
                groups.setdefault(key, []).append(r)
        for key, runs in groups.items():
            seeds = ", ".join(str(r.seed) for r in runs)
            text = f"{case}: {key} in {len(runs)}/{len(records)} runs (seeds {seeds})"
            times = [r.collisions[0][2] for r in runs if r.collisions]
            if times:
                text += f", at {min(times) / 1000:.2f}–{max(times) / 1000:.2f} s"
            lines.append(text)
    return lines


def json_report(exp: Experiment) -> dict[str, Any]:
    """Everything measured, JSON-ready."""
    o = exp.options
    scenarios = {}
    for row in exp.rows:
        records = exp.runs.get(row.case, [])
        predicted = exp.predictions.get(row.case, {})
        errors = [arrival_errors(r.durations_ms, predicted) for r in records]
        drift = summarise(errors, len(records))
        scenarios[row.case] = {
            "row": csv_record(row, o.semantics),
            "predicted_arrival_ms": predicted,
            "arrival_drift": {"runs": drift.runs, "samples": drift.samples,
                              "mean_abs_ms": _finite(drift.mean_abs_ms),
                              "max_abs_ms": drift.max_abs_ms,
                              "mean_signed_ms": _finite(drift.mean_signed_ms)},
            "runs": [r.to_json() for r in records],
        }
    return {"command": exp.command, "interrupted": exp.interrupted,
            "retried": [list(r) for r in exp.retried],
            "options": {"runs": o.runs, "time_scale": o.time_scale, "semantics": list(o.semantics),
                        "seed": o.seed, "max_states": o.max_states, "max_time_s": o.max_time_s,
                        "horizon_s": o.horizon_s, "predict": o.predict, "timing": o.timing,
                        "confidence": o.confidence, "workers": o.workers,
                        "params": list(o.params)},
            "scenarios": scenarios}


def _finite(x: float) -> float | None:
    return None if math.isnan(x) else round(x, 1)
