"""`check()`: load a scenario, search it, and report a verdict (the CLI's engine).

Exit codes of a `CheckResult`: 0 every property holds, 1 a property is
violated, 2 no answer (a limit was reached, the search was interrupted, or
random walks found nothing, which proves nothing). Bad input raises before
a result exists (`ScenarioError`, `PropertyError`, `NodeDefinitionError`).
The search always stops at the first violation (RMC does the same, R11), so
the scenario key `check.stop_at_first` is accepted but has no other value.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, final

from checker.properties import PropertySet, Violation
from checker.search import HOLDS, VIOLATED, Limits, Search, SearchStatistics
from checker.system import System
from checker.trace import build_trace, write_trace
from runtime.scenario import Scenario, ScenarioError, load_scenario


@final
@dataclass(frozen=True)
class CheckOptions:
    """How to check; None means "the scenario's `check:` setting, else the default"."""

    search: str | None = None
    walks: int = 100
    seed: int | None = None
    max_states: int | None = None
    max_time_s: float | None = None
    max_depth: int | None = None
    semantics: str | None = None
    profile: str | None = None
    trace_out: str | None = None
    debug_state: bool = False
    progress: Callable[[SearchStatistics], None] | None = field(default=None, compare=False)


@final
@dataclass
class CheckResult:
    """The verdict and what it cost."""

    scenario: str
    semantics: str
    search: str
    status: str
    reason: str
    properties: list[str]
    statistics: SearchStatistics
    violation: Violation | None = None
    trace: dict[str, Any] | None = None
    trace_path: str | None = None

    @property
    def rmc_transitions(self) -> int:
        """Transitions as RMC counts them: executed steps plus one per initial state (R10)."""
        return self.statistics.transitions + self.statistics.initial_states

    @property
    def exit_code(self) -> int:
        """0 holds, 1 violated, 2 no answer."""
        return {HOLDS: 0, VIOLATED: 1}.get(self.status, 2)

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready record of the result."""
        s = self.statistics
        return {
            "scenario": self.scenario, "semantics": self.semantics, "search": self.search,
            "verdict": self.status, "reason": self.reason,
            "violation": None if self.violation is None else {
                "property": self.violation.property, "kind": self.violation.kind,
                "message": self.violation.message, "shape": self.violation.shape},
            "properties": self.properties, "states": s.states, "transitions": s.transitions,
            "rmc_transitions": self.rmc_transitions, "initial_states": s.initial_states,
            "depth": s.depth,
            "wall_time_s": round(s.elapsed_s, 3), "peak_memory_mb": round(s.peak_rss_mb, 1),
            "trace": self.trace_path,
            "trace_steps": None if self.trace is None else len(self.trace["steps"]),
            "exit_code": self.exit_code,
        }

    def summary(self) -> str:
        """A human-readable summary, several lines."""
        s = self.statistics
        if self.status == HOLDS:
            verdict = "HOLDS: every property holds"
        elif self.status == VIOLATED and self.violation is not None:
            verdict = f"VIOLATED {self.violation.property}: {self.violation.message}"
        else:
            verdict = f"UNKNOWN: {self.reason}"
        lines = [f"twinfleet check {self.scenario} (semantics {self.semantics}, "
                 f"search {self.search})",
                 f"verdict: {verdict}",
                 "properties: " + "; ".join(self.properties),
                 f"states {s.states:,}  transitions {s.transitions:,} "
                 f"(RMC-style {self.rmc_transitions:,})  depth {s.depth}  "
                 f"initial states {s.initial_states}",
                 f"time {s.elapsed_s:.2f} s ({s.transitions_per_s:,.0f} transitions/s)  "
                 f"peak memory {s.peak_rss_mb:.0f} MB"]
        if self.trace is not None:
            where = self.trace_path or "(not written)"
            lines.append(f"trace: {where} ({len(self.trace['steps'])} steps, "
                         f"{self.trace['shape']})")
            if self.trace_path:
                lines.append(f"reproduce with: twinfleet replay {self.trace_path}")
        return "\n".join(lines)


def load(path: str | Path, *, profile: str | None = None,
         semantics: str | None = None) -> Scenario:
    """Load a scenario with optional profile/semantics overrides."""
    overrides: dict[str, Any] = {}
    if profile is not None:
        overrides["profile"] = profile
    if semantics is not None:
        overrides["semantics"] = semantics
    return load_scenario(path, overrides)


def _limit(value: Any, scenario_value: Any) -> Any:
    chosen = value if value is not None else scenario_value
    return None if chosen in (None, 0) else chosen


def limits_for(options: CheckOptions, check: Mapping[str, Any]) -> Limits:
    """Limits from the options, falling back to the scenario's `check:` block (0 = none)."""
    return Limits(max_states=_limit(options.max_states, check.get("max_states")),
                  max_time_s=_limit(options.max_time_s, check.get("max_time_s")),
                  max_depth=_limit(options.max_depth, check.get("max_depth")))


def check(path: str | Path, options: CheckOptions = CheckOptions()) -> CheckResult:
    """Check the scenario at `path`; write a trace to `options.trace_out` on a violation."""
    scenario = load(path, profile=options.profile, semantics=options.semantics)
    props = PropertySet.from_scenario(scenario)
    system = System(scenario, debug_state=options.debug_state, monitors=props)
    strategy = options.search or scenario.check.get("search") or "bfs"
    if strategy not in ("bfs", "dfs", "random"):
        raise ScenarioError(f"{path}: check.search: expected bfs, dfs or random, got {strategy!r}")
    search = Search(system, props, limits_for(options, scenario.check), progress=options.progress)
    seed = options.seed if options.seed is not None else scenario.seed
    outcome = search.run(strategy, walks=options.walks, seed=seed)
    result = CheckResult(str(path), system.semantics.name, strategy, outcome.status,
                         outcome.reason, props.names(), outcome.statistics, outcome.violation)
    if outcome.violation is not None and outcome.path is not None:
        result.trace = build_trace(system, outcome.violation, outcome.path,
                                   scenario_path=str(Path(path).resolve()), search=strategy)
        if options.trace_out:
            write_trace(result.trace, options.trace_out)
            result.trace_path = options.trace_out
    return result
