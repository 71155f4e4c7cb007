"""What a worker needs to build the coordinator's `System`, and the fingerprint it must match.

Node code reaches workers by import (the same twinfleet and node packages
installed on every machine); the scenario file is read on each worker. A
worker builds its system from a `SystemSpec` and refuses to start when its
`fingerprint` differs from the coordinator's: the scenario file's hash, the
rules the system applies, and the source of every node class.
"""

from __future__ import annotations

import dataclasses
import hashlib
import inspect
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, final

from twinfleet.checker.properties import PropertySet
from twinfleet.checker.reduction import Reduction
from twinfleet.checker.system import System


class ClusterError(Exception):
    """The cluster cannot run or finish the search (no verdict; exit 2)."""


@final
@dataclass(frozen=True)
class SystemSpec:
    """How to build the system of a check on another machine (picklable)."""

    scenario: str  # an absolute path to the scenario file
    semantics: str | None
    params: tuple[str, ...]
    flags: tuple[tuple[str, Any], ...]  # System's search flags (debug_state, verify...)
    timing: str | None = None
    ranges: tuple[tuple[str, Any], ...] = ()  # System's timing arguments from a timing model
    reduction: str | None = None  # "por": the partial-order reduction runs on the workers too

    def build(self) -> tuple[System, PropertySet, Reduction | None]:
        """The system, properties and reduction, as `checker.driver.check` builds them
        (a reduction learning level by level, `Publications.freeze`)."""
        from twinfleet.checker.reduction import plan
        from twinfleet.runtime.scenario.overrides import load

        scenario = load(self.scenario, semantics=self.semantics, params=self.params)
        props = PropertySet.from_scenario(scenario)
        system = System(scenario, properties=props, **dict(self.flags), **dict(self.ranges))
        reduction = None if self.reduction is None else plan(system, props, "bfs",
                                                             self.reduction)[0]
        if reduction is not None:
            reduction.freeze()
        return system, props, reduction


def fingerprint(system: System) -> dict[str, str]:
    """What must be equal on every machine: scenario, rules, node sources (hashes)."""
    scenario = system.scenario
    text = scenario.path.read_bytes() if scenario.path is not None else repr(scenario).encode()
    sources = hashlib.sha256()
    for cls in sorted({type(n) for n in system.nodes}, key=lambda c: c.__qualname__):
        try:  # the bytes of the file the class was imported from
            sources.update(Path(inspect.getfile(cls)).read_bytes())
        except (OSError, TypeError):  # a class without a source file: its name only
            sources.update(cls.__qualname__.encode())
    return {"scenario": hashlib.sha256(text).hexdigest(),
            "rules": hashlib.sha256(_canonical(system.rules).encode()).hexdigest(),
            "node sources": sources.hexdigest()}


def _canonical(value: Any) -> str:
    """`repr` whose sets and mappings are sorted: the same on every process (a frozenset's
    order follows string hashing, which each process seeds differently)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        shown = [(f.name, _canonical(getattr(value, f.name)))
                 for f in dataclasses.fields(value) if f.repr]
        return f"{type(value).__name__}({shown})"
    if isinstance(value, Mapping):
        return repr(sorted((_canonical(k), _canonical(v)) for k, v in value.items()))
    if isinstance(value, (set, frozenset)):
        return repr(sorted(_canonical(v) for v in value))
    if isinstance(value, (list, tuple)):
        return repr([_canonical(v) for v in value])
    return repr(value)


def mismatch(mine: dict[str, str], theirs: dict[str, str]) -> str | None:
    """Which part of two fingerprints differs, or None."""
    for part in ("scenario", "rules", "node sources"):
        if mine.get(part) != theirs.get(part):
            return part
    return None
