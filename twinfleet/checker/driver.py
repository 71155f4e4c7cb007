"""`check()`: load a scenario, search it, and report a verdict (the CLI's engine).

Exit codes of a `CheckResult`: 0 every property holds, 1 a property is
violated, 2 no answer (a limit was reached, the search was interrupted, or
random walks found nothing, which proves nothing), 4 a node breaks the node
contract (`checker.diagnosis`: no verdict, one line naming node, handler,
what differed and the fix, in `CheckResult.breach`). Bad input raises before
a result exists (`ScenarioError`, `PropertyError`, `NodeDefinitionError`).
The search stops at the first violation, as RMC's does.

`CheckOptions.checkpoint` saves the search to a file every
`checkpoint_every_s` seconds and when it stops early (a limit, Ctrl-C);
`CheckOptions.resume` continues such a file with the settings it was started
with (the scenario file must be unchanged: its hash is recorded).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, final

from twinfleet.checker import checkpoint as ckpt
from twinfleet.checker.checkpoint import CheckpointError
from twinfleet.checker.collector import seldom_collections
from twinfleet.checker.diagnosis import (
    CONTRACT_KINDS,
    FIX_HIDDEN,
    ContractBreachError,
    breach_line,
)
from twinfleet.checker.growth import HINT, GrowthNote
from twinfleet.checker.options import (
    MIN_WIDTH,
    REDUCE_FROM,
    ReductionMode,
    SearchOrder,
    Semantics,
)
from twinfleet.checker.outcome import INTERRUPTED_REASON, Limits, Outcome, SearchStatistics
from twinfleet.checker.properties import PropertySet, PropertyViolation
from twinfleet.checker.reduction import Reduction, describe, plan
from twinfleet.checker.search import Search
from twinfleet.checker.system import System
from twinfleet.checker.timing import AssumedTiming
from twinfleet.runtime.contract.kinds import EXIT_INTERRUPTED, FailureKind, Status
from twinfleet.runtime.contract.node import NodeSpec
from twinfleet.runtime.contract.tracefile import write_trace
from twinfleet.runtime.scenario.config import SEARCHES, CheckConfig, Fairness
from twinfleet.runtime.scenario.lint import lint_scenario
from twinfleet.runtime.scenario.overrides import load
from twinfleet.runtime.scenario.property_fields import check_property_fields
from twinfleet.runtime.scenario.spec import Scenario, ScenarioError, resolve_scenario


@final
@dataclass(frozen=True)
class CheckOptions:
    """How to check; None means "the scenario's `check:` setting, else the default".
    `search`, `semantics` and `reduction` may be given as their names ("dfs").

    Raises:
        ScenarioError: a search, semantics or reduction that does not exist.
    """

    search: SearchOrder | None = None
    walks: int = 100
    seed: int | None = None
    max_states: int | None = None
    max_time_s: float | None = None
    max_depth: int | None = None
    semantics: Semantics | None = None
    trace_out: str | None = None
    debug_state: bool = False
    exact_states: bool = False
    check_determinism: bool = False
    transition_cache: bool = True
    verify: bool = True
    checkpoint: str | None = None
    checkpoint_every_s: float = 300.0
    resume: str | None = None
    reduction: ReductionMode | None = None
    timing: str | None = None  # a timing model whose bounds are the latency ranges
    fairness: Fairness | None = None  # what eventually counterexamples assume (check.fairness)
    params: tuple[str, ...] = ()  # parameter overrides, as `launch` takes them (r1.speed:=0.4)
    workers: int = 1  # Ray workers for the search (checker.cluster); 1 with no cluster: here
    cluster: str | None = None  # a Ray cluster to join instead of starting a local one
    min_width: int = MIN_WIDTH  # frontier width at which a search moves to the cluster
    reduce_from: int = REDUCE_FROM  # worlds searched before por starts (0: from the first)
    report: Callable[[str], None] | None = field(default=None, compare=False)
    progress: Callable[[SearchStatistics], None] | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        for name, kind in (("search", SearchOrder), ("semantics", Semantics),
                           ("reduction", ReductionMode), ("fairness", Fairness)):
            value = getattr(self, name)
            if value is not None and not isinstance(value, kind):
                try:
                    object.__setattr__(self, name, kind(value))
                except ValueError:
                    raise ScenarioError(f"unknown {name} {value!r}; expected one of "
                                        f"{', '.join(kind)}") from None


@final
@dataclass
class CheckResult:
    """The verdict and what it cost."""

    scenario: str
    semantics: str
    search: str
    status: Status
    reason: str
    properties: list[str]
    statistics: SearchStatistics
    violation: PropertyViolation | None = None
    trace: dict[str, Any] | None = None
    trace_path: str | None = None
    checkpoint: str | None = None
    resumed_from: str | None = None
    breach: str | None = None  # the one-line diagnosis of a contract breach
    warnings: list[str] = field(default_factory=list)  # load-time lint (runtime.scenario.lint)
    reduction: str = "none"
    reduction_statistics: dict[str, int] | None = None
    params: tuple[str, ...] = ()  # the parameter overrides checked with
    fairness: str = "none"  # what a counterexample to an eventually property may assume
    engine: str | None = None  # where the search ran, when workers were asked for
    handler_runs: int = 0  # handlers run by this process (its outcome cache missed)
    timing: AssumedTiming | None = None  # the latency and timer lateness the verdict assumed

    @property
    def interrupted(self) -> bool:
        """The search was stopped by Ctrl-C (no verdict; the caller stops too)."""
        return self.status is Status.UNKNOWN and self.reason == INTERRUPTED_REASON

    @property
    def rmc_transitions(self) -> int:
        """Transitions as RMC counts them: executed steps plus one per initial state (R10)."""
        return self.statistics.transitions + self.statistics.initial_states

    @property
    def exit_code(self) -> int:
        """0 holds, 1 violated, 2 no answer, 4 a node breaks the node contract, 130
        interrupted (`twinfleet.cli` makes it 143 when the signal was SIGTERM)."""
        if self.status is Status.UNKNOWN and self.reason == INTERRUPTED_REASON:
            return EXIT_INTERRUPTED
        return self.status.exit_code

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready record of the result."""
        s = self.statistics
        return {
            "scenario": self.scenario, "semantics": self.semantics, "search": self.search,
            "verdict": self.status, "reason": self.reason, "breach": self.breach,
            "warnings": self.warnings,
            "violation": None if self.violation is None else {
                "property": self.violation.property, "kind": self.violation.kind,
                "message": self.violation.message, "shape": self.violation.shape},
            "properties": self.properties, "states": s.states, "transitions": s.transitions,
            "rmc_transitions": self.rmc_transitions, "initial_states": s.initial_states,
            "depth": s.depth,
            "wall_time_s": round(s.elapsed_s, 3), "peak_memory_mb": round(s.peak_rss_mb, 1),
            "store_bytes": s.store_bytes, "bytes_per_state": round(s.bytes_per_state, 1),
            "digest_bits": s.digest_bits, "collision_probability": s.collision_probability,
            "checkpoint": self.checkpoint, "resumed_from": self.resumed_from,
            "trace": self.trace_path,
            "trace_steps": None if self.trace is None else len(self.trace["steps"]),
            "reduction": self.reduction, "reduction_statistics": self.reduction_statistics,
            "params": list(self.params), "fairness": self.fairness, "engine": self.engine,
            "timing": None if self.timing is None else self.timing.to_json(),
            "growth": [n.to_json() for n in self.growth_notes()],
            "exit_code": self.exit_code,
        }

    def summary(self) -> str:
        """A human-readable summary, several lines."""
        s = self.statistics
        if self.status is Status.HOLDS:
            verdict = "HOLDS: every property holds"
        elif self.status is Status.BREACH:
            verdict = f"CONTRACT BREACH (no verdict): {self.breach}"
        elif self.status is Status.VIOLATED and self.violation is not None:
            verdict = f"VIOLATED {self.violation.property}: {self.violation.message}"
        else:
            verdict = f"UNKNOWN: {self.reason}"
        lines = [f"twinfleet check {self.scenario} (semantics {self.semantics}, "
                 f"search {self.search})" + (f" with {' '.join(self.params)}"
                                              if self.params else ""),
                 f"verdict: {verdict}",
                 "properties: " + "; ".join(self.properties),
                 *([f"timing: {self.timing.line()}"] if self.timing is not None else []),
                 f"states {s.states:,}  transitions {s.transitions:,} "
                 f"(RMC-style {self.rmc_transitions:,})  depth {s.depth}  "
                 f"initial states {s.initial_states}",
                 f"time {s.elapsed_s:.2f} s ({s.transitions_per_s:,.0f} transitions/s"
                 + ("" if s.attempt_s is None else
                    f"; {s.attempt_transitions_per_s:,.0f}/s in the {_seconds(s.attempt_s)} since "
                    "the search last started again") + f")  peak memory {s.peak_rss_mb:.0f} MB",
                 f"visited-state store {s.store_bytes / 2**20:.1f} MB "
                 f"({s.bytes_per_state:.0f} B/state, {s.digest_bits}-bit digests, "
                 f"collision probability <= {s.collision_probability:.1e})",
                 f"reduction: {self.reduction}"]
        lines += self.growth_lines()
        if self.engine:
            lines.append(f"engine: {self.engine}")
        if self.resumed_from:
            lines.append(f"resumed from checkpoint {self.resumed_from}")
        if self.checkpoint:
            lines.append(f"checkpoint: {self.checkpoint} (continue with: twinfleet check "
                         f"--resume {self.checkpoint})")
        if self.trace is not None:
            where = self.trace_path or "(not written)"
            lines.append(f"trace: {where} ({len(self.trace['steps'])} steps, "
                         f"{self.trace['shape']})")
            if self.trace_path:
                lines.append(f"reproduce with: twinfleet replay {self.trace_path}")
                lines.append(f"read it step by step: twinfleet trace show {self.trace_path}")
        return "\n".join(lines)

    def growth_notes(self) -> tuple[GrowthNote, ...]:
        """The fields that kept taking new values, when no limit but the search's end
        should have stopped it (a search that finished has none to report)."""
        return self.statistics.growth if self.status is Status.UNKNOWN else ()

    def growth_lines(self) -> list[str]:
        """Summary lines naming what kept the state space growing, or a hint when a limit
        stopped a deep search and no field stood out."""
        notes = self.growth_notes()
        if notes:
            return [f"state growth: {n.describe()}" for n in notes]
        s = self.statistics
        if self.status is Status.UNKNOWN and s.depth >= _DEEP and self.search != "random" \
                and "max-depth" not in self.reason:
            return [f"hint: the search was still going deeper (depth {s.depth:,}); if some "
                    "state never repeats (a counter, a drifting float, a growing list), "
                    f"{HINT}"]
        return []


_DEEP = 1_000  # a search stopped by a limit this deep gets the hint of `growth_lines`


def system_for_trace(trace: Mapping[str, Any]) -> tuple[System, PropertySet]:
    """The system a trace was found on (its scenario, parameters, semantics, latency and flags),
    with the scenario's properties watching it, as `twinfleet replay` re-executes it."""
    if trace.get("scenario") is None:
        raise ScenarioError("the trace names no scenario file (its scenario was built in "
                            "Python): replay it with checker.replay(System(scenario), trace)")
    scenario = load(trace["scenario"], semantics=trace.get("semantics"),
                    params=trace.get("params") or ())
    props = PropertySet.from_scenario(scenario)
    latency = trace.get("latency")
    per_name = tuple((name, (span[0], span[1])) for name, span in trace.get("topic_latency") or ())
    system = System(scenario, latency=tuple(latency) if latency else None,
                    topic_latency=per_name,
                    global_priority=trace.get("global_priority"),
                    debug_state=bool(trace.get("debug_state")), properties=props,
                    check_determinism=bool(trace.get("check_determinism")))
    return system, props


def _limit(value: Any, scenario_value: Any) -> Any:
    chosen = value if value is not None else scenario_value
    return None if chosen in (None, 0) else chosen


def limits_for(options: CheckOptions, check: CheckConfig) -> Limits:
    """Limits from the options, falling back to the scenario's `check:` block (0 = none)."""
    return Limits(max_states=_limit(options.max_states, check.max_states),
                  max_time_s=_limit(options.max_time_s, check.max_time_s),
                  max_depth=_limit(options.max_depth, check.max_depth))


def check(scenario: str | Path | Scenario | None,
          options: CheckOptions = CheckOptions()) -> CheckResult:
    """Check a scenario (a file, a shipped example's name, or a `Scenario` built in Python);
    write a trace to `options.trace_out` on a violation.

    With `options.resume`, continue that checkpoint (`scenario` may then be None).
    """
    scenario, path, data = _to_check(scenario, options)
    meta = data["meta"] if data is not None else {}
    check_property_fields(scenario)
    props = PropertySet.from_scenario(scenario)
    warnings = [str(w) for w in lint_scenario(scenario)]
    flags = {key: meta.get(key, getattr(options, key)) for key in _SEARCH_FLAGS}
    system = System(scenario, properties=props, **flags, **_timing_ranges(scenario, options))
    asked = options.search or scenario.check.search
    strategy = _strategy(meta.get("strategy") or asked or "bfs")
    reduction, reduction_name = _planned(system, props, strategy,
                                         meta.get("reduction") or options.reduction,
                                         options.reduce_from)
    meta = {"scenario": None if path is None else str(path.resolve()),
            "sha256": None if path is None else ckpt.file_sha256(path),
            "semantics": system.semantics.value,
            "strategy": strategy, "reduction": reduction_name.split()[0],
            "params": list(meta.get("params", options.params)), **flags}
    search = Search(system, props, limits_for(options, scenario.check), progress=options.progress,
                    checkpoint=options.checkpoint or options.resume,
                    checkpoint_every_s=options.checkpoint_every_s, checkpoint_meta=meta,
                    reduction=reduction)
    resumed_cluster = data is not None and _distributed_checkpoint(data["meta"])
    if data is not None and not resumed_cluster:
        search.restore(data)
    seed = options.seed if options.seed is not None else scenario.seed
    engine, outcome = None, None
    try:
        with seldom_collections():
            if options.workers > 1 or options.cluster is not None or resumed_cluster:
                outcome, engine = _distributed(system, props, strategy, reduction, options,
                                               path, scenario, flags, meta, asked != "bfs",
                                               data if resumed_cluster else None)
            if outcome is None:
                outcome = search.run(strategy, walks=options.walks, seed=seed)
    except ContractBreachError as exc:  # found while rebuilding a path (checker.paths)
        return _breach_result(scenario, system, strategy, props, str(exc), search, warnings)
    if outcome.violation is not None and (breach := _breach_of(system, outcome.violation)):
        return _breach_result(scenario, system, strategy, props, breach, search, warnings)
    result = CheckResult(scenario.source, system.semantics.value, strategy, outcome.status,
                         outcome.reason, _property_names(system, props), outcome.statistics,
                         outcome.violation, checkpoint=outcome.checkpoint,
                         resumed_from=options.resume, warnings=warnings,
                         reduction=describe(reduction, reduction_name, strategy),
                         reduction_statistics=None if reduction is None else
                         reduction.statistics(), params=tuple(meta["params"]),
                         fairness=scenario.check.fairness, engine=engine,
                         handler_runs=system.runner.handler_runs,
                         timing=_assumed_timing(scenario, system, options))
    if outcome.violation is not None and outcome.counterexample is not None:
        breach = _traced(result, system, outcome, meta, options.trace_out)
        if breach is not None:
            return _breach_result(scenario, system, strategy, props, breach, search, warnings)
    return result


def _to_check(scenario: str | Path | Scenario | None, options: CheckOptions
              ) -> tuple[Scenario, Path | None, dict[str, Any] | None]:
    """The scenario `check` is given, its file (if any) and the checkpoint it resumes
    (if any), after checking that they fit together."""
    data, path = None, _scenario_file(scenario)
    if options.resume is not None:
        data = ckpt.load(options.resume)
        path = _resume_path(path, options, data["meta"])
    if path is None and not isinstance(scenario, Scenario):
        raise ScenarioError("no scenario file given (pass one, or --resume CHECKPOINT)")
    meta = data["meta"] if data is not None else {}
    scenario = _scenario(scenario if isinstance(scenario, Scenario) else path, options, meta)
    if path is None and options.checkpoint is not None:
        raise ScenarioError(f"{scenario.source}: a checkpoint needs a scenario file")
    return scenario, path, data


def _planned(system: System, props: PropertySet, strategy: str, asked: str | None,
             reduce_from: int) -> tuple[Reduction | None, str]:
    """The reduction `checker.reduction.plan` makes for the search; one that does not fit
    the scenario is bad input."""
    try:
        return plan(system, props, strategy, asked, reduce_from)
    except ValueError as exc:
        raise ScenarioError(f"{system.scenario.source}: {exc}") from None


def _strategy(strategy: str) -> str:
    """`strategy`, if it names a search."""
    if strategy not in SEARCHES:
        raise ScenarioError(f"search: expected {', '.join(SEARCHES)}, got {strategy!r}")
    return strategy


def _traced(result: CheckResult, system: System, outcome: Outcome, meta: Mapping[str, Any],
            trace_out: str | None) -> str | None:
    """Give `result` the trace of the outcome's counterexample, written to `trace_out` if
    given; the breach line instead if the counterexample does not run again."""
    assert outcome.violation is not None and outcome.counterexample is not None
    try:
        from twinfleet.checker.trace import build_trace  # here: a check that holds needs none

        result.trace = build_trace(system, outcome.violation, outcome.counterexample,
                                   scenario_path=meta["scenario"], search=result.search,
                                   scenario_sha256=meta["sha256"], params=meta["params"])
    except IndexError:  # the path's events are not there when it runs again
        return breach_line(
            FailureKind.NONDETERMINISM, "", "(unknown)", "the counterexample does not run "
            "again from its initial world: some handler depends on something outside "
            "self.state" + ("" if system.runner.verify else " (the contract checks were "
                            "off: rerun without --no-contract-checks to name it)") +
            f"; fix: {FIX_HIDDEN}")
    if trace_out:
        write_trace(result.trace, trace_out)
        result.trace_path = trace_out
    return None


def _distributed_checkpoint(meta: Mapping[str, Any]) -> bool:
    from twinfleet.checker.cluster import is_distributed_checkpoint

    return is_distributed_checkpoint(meta)


def _distributed(system: System, props: PropertySet, strategy: str, reduction: Reduction | None,
                 options: CheckOptions, path: Path | None, scenario: Scenario,
                 flags: Mapping[str, Any], meta: Mapping[str, Any], unordered: bool,
                 resume: Mapping[str, Any] | None) -> tuple[Outcome | None, str]:
    """The outcome of the search on Ray workers (`checker.cluster`), from the checkpoint
    `resume` if given, or None and why it runs here. `unordered`: no strict BFS was asked
    for, so the workers may search in a relaxed order where nothing else needs levels."""
    from twinfleet.checker.cluster import Checkpointing, SystemSpec, distributed, why_local

    local = why_local(strategy)
    if local is not None:
        return None, local
    if path is None or options.exact_states:
        raise ScenarioError("--workers/--cluster need a scenario file and no --exact-states")
    if options.resume is not None and resume is None:
        raise CheckpointError(f"{options.resume}: written by the search in one process; "
                              "continue it without --workers/--cluster")
    saving = options.checkpoint or options.resume
    timing = _timing_ranges(scenario, options)
    spec = SystemSpec(str(path.resolve()), system.semantics.value,
                      tuple(options.params), tuple(sorted(flags.items())), options.timing,
                      tuple(sorted(timing.items())),
                      None if reduction is None else meta["reduction"])
    limits = limits_for(options, scenario.check)
    relaxed = unordered and reduction is None and limits.max_depth is None and saving is None
    run = distributed(system, props, limits, spec, workers=options.workers, relaxed=relaxed,
                      address=options.cluster, min_width=options.min_width,
                      report=options.report, resume=resume, reduction=reduction,
                      checkpointing=None if saving is None else
                      Checkpointing(saving, options.checkpoint_every_s, meta))
    note = run.note if strategy == "bfs" or relaxed else \
        f"{run.note}; strict BFS order instead of {strategy}"
    return run.outcome, note


def _seconds(span: float) -> str:
    """A span as a summary says it: seconds, or milliseconds below one second."""
    return f"{span:.1f} s" if span >= 1 else f"{span * 1000:.1f} ms"


def _timing_ranges(scenario: Scenario, options: CheckOptions) -> dict[str, Any]:
    """`System` arguments that make a timing model's bounds the latency ranges and the
    timers' lateness (none without `options.timing`)."""
    if options.timing is None:
        return {}
    from twinfleet.checker.timing import load_timing

    topology = System(scenario).topology
    model = load_timing(options.timing)
    default, per = model.ranges(set(topology.subscribers) | set(topology.servers))
    ranges: dict[str, Any] = {"latency": default, "topic_latency": per}
    if model.timer_lateness.bounds[1] > 0:  # else the scenario's check.timer_lateness holds
        ranges["timer_lateness"] = model.timer_lateness.bounds
    return ranges


def _assumed_timing(scenario: Scenario, system: System, options: CheckOptions) -> AssumedTiming:
    """The latency ranges and timer lateness the search branched on and where they come
    from."""
    if options.timing is not None:
        source = f"the bounds of --timing {options.timing}, every value a branch"
    elif scenario.check.latency:
        source = "the scenario's check.latency, every value a branch"
    else:
        source = "the scenario, which sets no check.latency: every message is due when sent"
    settings = system.settings
    return AssumedTiming(settings.latency, settings.topic_latency,
                         settings.timer_lateness or (0, 0), source)


def _property_names(system: System, props: PropertySet) -> list[str]:
    names = props.names()
    if system.runner.verify:
        names.append("node contract (new handler runs probed and run twice)" if not
                     system.check_determinism else
                     "node contract (every transition probed and run twice)")
    return names


_DECORATORS = {"start": "on_start"}  # HandlerSpec.kind -> the decorator's name


def _breach_of(system: System, violation: PropertyViolation) -> str | None:
    """The one-line diagnosis of a violation that is a contract breach, or None."""
    failure = violation.failure
    if failure is None or failure.kind not in CONTRACT_KINDS:
        return None
    handler = failure.handler
    if failure.node in system.index:  # name the decorator too: "go (@on_start)"
        node = system.nodes[system.index[failure.node]]
        spec = NodeSpec.of(type(node)).by_method(handler)
        if spec is not None:
            handler = f"{handler} (@{_DECORATORS.get(spec.kind, spec.kind)})"
    return breach_line(failure.kind, failure.node, handler, failure.message)


def _breach_result(scenario: Scenario, system: System, strategy: str, props: PropertySet,
                   breach: str, search: Search, warnings: list[str]) -> CheckResult:
    """The result of a search stopped by a node that breaks the contract (exit 4): no
    verdict, and no trace, since a breach is not a path the nodes would take again."""
    return CheckResult(scenario.source, system.semantics.value, strategy, Status.BREACH,
                       "a node breaks the node contract", _property_names(system, props),
                       search.statistics(), breach=breach, warnings=warnings)


_SEARCH_FLAGS = ("debug_state", "exact_states", "check_determinism", "transition_cache",
                 "verify")


def _scenario_file(scenario: str | Path | Scenario | None) -> Path | None:
    """The file a scenario argument names (a shipped example's name resolved), if any."""
    if isinstance(scenario, Scenario):
        return scenario.path
    return None if scenario is None else resolve_scenario(scenario)


def _scenario(scenario: Path | Scenario | None, options: CheckOptions,
              meta: Mapping[str, Any]) -> Scenario:
    """The scenario to check, with the semantics and parameters of the options or checkpoint."""
    semantics = meta.get("semantics", options.semantics)
    params = meta.get("params", options.params)
    if not isinstance(scenario, Scenario):
        assert scenario is not None  # check() refuses a missing scenario file first
        return _with_fairness(load(scenario, semantics=semantics, params=params),
                              options.fairness)
    scenario = _with_fairness(scenario, options.fairness)
    if params:
        raise ScenarioError(f"{scenario.source}: the parameters of a scenario built in Python "
                            "are given when it is built (Scenario.build(..., params=...))")
    return scenario if semantics is None else dataclasses.replace(scenario, semantics=semantics)


def _with_fairness(scenario: Scenario, fairness: Fairness | None) -> Scenario:
    """`scenario` with the fairness the options ask for (None: its own `check.fairness`)."""
    if fairness is None:
        return scenario
    return dataclasses.replace(scenario, check=dataclasses.replace(scenario.check,
                                                                   fairness=fairness))


def _resume_path(path: Path | None, options: CheckOptions,
                 meta: Mapping[str, Any]) -> Path:
    """The scenario a checkpoint was written for, after checking it still fits."""
    recorded = meta["scenario"]
    where = options.resume
    if path is not None and Path(path).resolve() != Path(recorded):
        raise CheckpointError(f"{where}: written for {recorded}, not {path}")
    if not Path(recorded).is_file():
        raise CheckpointError(f"{where}: its scenario {recorded} no longer exists")
    if ckpt.file_sha256(recorded) != meta["sha256"]:
        raise CheckpointError(f"{where}: {recorded} changed since the checkpoint was written")
    if options.params and list(options.params) != meta.get("params", []):
        raise CheckpointError(f"{where}: written with parameters {meta.get('params', [])}, "
                              f"cannot resume with {list(options.params)}")
    for key, value in (("semantics", options.semantics), ("strategy", options.search)):
        if value is not None and value != meta[key]:
            raise CheckpointError(f"{where}: written with {key} {meta[key]}, cannot resume "
                                  f"with {value}")
    if options.reduction is not None and options.reduction != meta.get("reduction", "none"):
        raise CheckpointError(f"{where}: written with reduction {meta.get('reduction', 'none')}, "
                              f"cannot resume with {options.reduction}")
    for key in _SEARCH_FLAGS:
        if getattr(options, key) != getattr(CheckOptions, key) and \
                getattr(options, key) != meta[key]:
            raise CheckpointError(f"{where}: written with {key}={meta[key]}, cannot resume "
                                  f"with {getattr(options, key)}")
    return Path(recorded)
