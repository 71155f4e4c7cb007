"""Helpers for checker tests: write a scenario from Python data, check it, replay its trace."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from twinfleet.checker import CheckOptions, CheckResult, PropertySet, System, check, replay
from twinfleet.checker.driver import load

M = "tests.checker.models:"


def node(name: str, cls: str, priority: int | None = None, **params: Any) -> dict[str, Any]:
    """One `nodes:` entry using a class of tests/checker/models.py."""
    entry: dict[str, Any] = {"name": name, "class": M + cls}
    if params:
        entry["params"] = params
    if priority is not None:
        entry["priority"] = priority
    return entry


def scenario(tmp_path: Path, nodes: list[dict[str, Any]], *, properties: list[dict[str, Any]]
             | None = None, semantics: str = "ros", name: str = "t", **check: Any) -> Path:
    """Write a scenario YAML into tmp_path and return its path."""
    doc: dict[str, Any] = {"name": name, "semantics": semantics, "nodes": nodes}
    if properties:
        doc["properties"] = properties
    if check:
        doc["check"] = check
    path = tmp_path / f"{name}-{semantics}.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def run(path: Path, **options: Any) -> CheckResult:
    """check() with a trace file in the scenario's directory; unreduced unless `reduction`
    is given (hand counts and traces are of the full graph; None: the default). A reduction
    runs from the first world (`reduce_from` 0): these systems are far smaller than the
    worlds a search stores before the reduction starts by default (`checker.late_start`)."""
    options.setdefault("trace_out", str(path.with_suffix(".trace.json")))
    options.setdefault("reduction", "none")
    options.setdefault("reduce_from", 0)
    return check(path, CheckOptions(**options))


def counts(result: CheckResult) -> tuple[int, int, int]:
    """(states, transitions, RMC-style transitions)."""
    s = result.statistics
    return (s.states, s.transitions, result.rmc_transitions)


def steps(result: CheckResult) -> list[tuple[str, str, tuple[int, ...]]]:
    """The trace as (node, handler, choices) per step."""
    assert result.trace is not None
    return [(s["node"], s["handler"], tuple(s["choices"])) for s in result.trace["steps"]]


def replay_confirms(result: CheckResult, *, debug_state: bool = False) -> bool:
    """Replay the result's trace on a fresh System; True if the violation is reproduced."""
    assert result.trace is not None
    trace = result.trace
    scenario_ = load(trace["scenario"], semantics=trace["semantics"])
    props = PropertySet.from_scenario(scenario_)
    system = System(scenario_, debug_state=debug_state, properties=props)
    return replay(system, trace, props).confirmed
