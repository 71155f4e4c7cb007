"""One point of a sweep: the check it stands for, run in this process, and its result.

`run_point` is what every engine runs, serially or as a Ray task: the same function, so
a distributed sweep answers what a serial one answers. A point's overrides go through the
path `twinfleet check c1a r1.speed:=0.4` takes (`checker.driver.check` with `params`),
so what a sweep reports for a point is what a single check of it reports.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, final

from twinfleet.checker.options import SearchChoices
from twinfleet.sweep.grid import Point, Target, format_value


@final
@dataclass(frozen=True)
class SweepSettings:
    """What every point of a sweep shares: the scenario file and how to search it."""

    scenario: str  # a resolved scenario file
    targets: tuple[tuple[str, Target], ...]  # each axis name and what it sets
    fixed: Point = ()  # settings every point shares (`sweep c2a '*.allow_unsafe_speed:=true'`)
    check: SearchChoices = SearchChoices()  # how every point is searched, as `check` takes it
    trace_dir: str | None = None  # where a violating point's trace goes (replayable)


@final
@dataclass(frozen=True)
class PointResult:
    """What the check of one point answered (one row of the sweep's tables)."""

    point: Point
    verdict: str  # a `Status` value: holds, violated, unknown, contract breach
    violated: str | None  # the violated property's name
    states: int
    transitions: int
    time_s: float  # wall time of the check
    violation_time_ms: int | None  # fleet time of the counterexample's last step
    reason: str = ""
    trace: str | None = None
    errors: tuple[str, ...] = field(default=())

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready record (the point as a name → value mapping)."""
        record = asdict(self)
        record["point"] = [[name, value] for name, value in self.point]
        record["errors"] = list(self.errors)
        return record

    @classmethod
    def from_json(cls, record: Mapping[str, Any]) -> PointResult:
        """The inverse of `to_json`."""
        return cls(**{**record, "point": tuple((n, v) for n, v in record["point"]),
                      "errors": tuple(record.get("errors", ()))})


def run_point(settings: SweepSettings, point: Point, name: str = "") -> PointResult:
    """Check one point; bad input for this point (an unsafe speed, say) is its result
    with verdict ``error``, not the sweep's end.

    Raises:
        KeyboardInterrupt: Ctrl-C stopped the check (its answer is no answer: a resumed
            sweep must run the point again, so it is not a result).
    """
    from twinfleet.checker.commands import bad_input_errors
    from twinfleet.checker.diagnosis import ContractBreachError

    started = time.perf_counter()
    try:
        result = _checked(settings, point, name)
    # a node's Params refusing a value (robot: an unsafe speed) raises ValueError
    except (*bad_input_errors(), ContractBreachError, ValueError) as exc:  # type: ignore[misc]
        return PointResult(point, "error", None, 0, 0, round(time.perf_counter() - started, 3),
                           None, reason=" ".join(str(exc).split()))
    return result


def _checked(settings: SweepSettings, point: Point, name: str) -> PointResult:
    from twinfleet.checker.driver import CheckOptions, check

    values = dict(settings.fixed + point)
    targets = dict(settings.targets)
    semantics = next((values[n] for n, t in targets.items() if t is Target.SEMANTICS), None)
    params = node_overrides(settings.scenario, settings.fixed + point, targets)
    trace_out = None
    if settings.trace_dir and name:
        trace_out = str(Path(settings.trace_dir) / f"{name}.trace.json")
    options = CheckOptions(**settings.check.fields(), semantics=semantics,
                           params=tuple(params), trace_out=trace_out)
    check_block = {n.removeprefix("check."): v for n, v in settings.fixed + point
                   if targets[n] is Target.CHECK}
    scenario: Any = settings.scenario
    if check_block:  # a changed check: block makes a scenario built here, not a file's
        scenario = with_check(settings.scenario, params, check_block, options)
        options = dataclasses.replace(options, params=(), trace_out=None, semantics=None)
    result = check(scenario, options)
    if result.interrupted:
        raise KeyboardInterrupt
    stats = result.statistics
    steps = (result.trace or {}).get("steps")
    return PointResult(point, str(result.status.value),
                       None if result.violation is None else result.violation.property,
                       stats.states, stats.transitions, round(stats.elapsed_s, 3),
                       None if result.trace is None else int(steps[-1]["time"]) if steps else 0,
                       reason=result.reason if result.violation is None else
                       result.violation.message, trace=result.trace_path)


def with_check(path: str, params: Sequence[str], block: Mapping[str, Any],
               options: Any) -> Any:
    """Scenario `path` with `params` applied and keys of its ``check:`` block replaced,
    validated as a file's own settings are."""
    from twinfleet.runtime.scenario.overrides import load_with_params
    from twinfleet.runtime.scenario.spec import parse_yaml

    doc = parse_yaml(Path(path).read_text())
    overrides: dict[str, Any] = {"check": {**(doc.get("check") or {}), **block}}
    if options.semantics is not None:
        overrides["semantics"] = options.semantics
    return load_with_params(path, params, overrides)


def node_overrides(scenario: str, point: Point, targets: Mapping[str, Target]) -> list[str]:
    """The point's parameter overrides as `check` takes them (``r1.speed:=0.4``); a
    ``*.NAME`` axis becomes one override per node whose parameters have NAME."""
    words: list[str] = []
    for axis, value in point:
        target, text = targets[axis], format_value(value)
        if target in (Target.NODE, Target.COMMON):
            words.append(f"{axis}:={text}")
        elif target is Target.EVERY_NODE:
            key = axis.removeprefix("*.")
            words.extend(f"{node}.{key}:={text}" for node in nodes_with(scenario, key))
    return words


def nodes_with(scenario: str, key: str) -> Sequence[str]:
    """The nodes of a scenario file whose parameters have field `key`."""
    from twinfleet.runtime.scenario.spec import load_scenario

    loaded = load_scenario(scenario)
    return [cfg.name for cfg in loaded.nodes
            if key in {f.name for f in dataclasses.fields(cfg.cls.Params)}]
