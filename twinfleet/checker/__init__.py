"""twinfleet's checker: explores every interleaving of the same node code the fleet runs.

Imports nothing from Zenoh or asyncio. Entry points: `check()` (scenario file →
`CheckResult`), `System` + `Search` for programmatic use, `replay()` for traces,
and `checker.commands.register` for the CLI.

Modules: `world` (worlds, events, identities), `semantics` (every enabling
rule), `transition` (actions, steps and what they did), `system` (the model:
initial worlds, actions, the step function; handler outcomes cached),
`topology` (the node graph), `runner` (running one handler), `faults`
(optional `check:` settings: latency, deadlines, queue bounds,
drop/duplicate/crash faults), `store` (visited states: 64-bit digest table,
parents, edges), `paths` (paths, lassos), `outcome` (limits, statistics,
counterexamples, verdicts), `search` (BFS/DFS), `walks` (random walks),
`checkpoint` (save and resume a search), `properties`, `trace`, `check`,
`commands`, `options` (the named choices an argument parser offers).

The names below load on first use, so a command line that only parses arguments loads
none of the search.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from twinfleet.checker.checkpoint import CheckpointError
    from twinfleet.checker.driver import CheckOptions, CheckResult, check
    from twinfleet.checker.faults import CheckSettings
    from twinfleet.checker.options import Semantics
    from twinfleet.checker.outcome import Counterexample, Limits, Outcome, SearchStatistics
    from twinfleet.checker.properties import PropertyError, PropertySet, PropertyViolation
    from twinfleet.checker.search import Search, bfs, dfs, random_walk
    from twinfleet.checker.semantics import Rules
    from twinfleet.checker.store import StateStore
    from twinfleet.checker.system import System
    from twinfleet.checker.trace import NondeterminismError, ReplayResult, build_trace, replay
    from twinfleet.checker.transition import (
        Action,
        Crash,
        Drop,
        Failure,
        RunEvent,
        Step,
        Transition,
    )
    from twinfleet.checker.world import Event, World

_HOMES: dict[str, str] = {
    "Action": "twinfleet.checker.transition",
    "CheckOptions": "twinfleet.checker.driver",
    "CheckResult": "twinfleet.checker.driver",
    "CheckSettings": "twinfleet.checker.faults",
    "CheckpointError": "twinfleet.checker.checkpoint",
    "Counterexample": "twinfleet.checker.outcome",
    "Crash": "twinfleet.checker.transition",
    "Drop": "twinfleet.checker.transition",
    "Event": "twinfleet.checker.world",
    "Failure": "twinfleet.checker.transition",
    "Limits": "twinfleet.checker.outcome",
    "NondeterminismError": "twinfleet.checker.trace",
    "Outcome": "twinfleet.checker.outcome",
    "PropertyError": "twinfleet.checker.properties",
    "PropertySet": "twinfleet.checker.properties",
    "PropertyViolation": "twinfleet.checker.properties",
    "ReplayResult": "twinfleet.checker.trace",
    "Rules": "twinfleet.checker.semantics",
    "RunEvent": "twinfleet.checker.transition",
    "Search": "twinfleet.checker.search",
    "SearchStatistics": "twinfleet.checker.outcome",
    "Semantics": "twinfleet.checker.options",
    "StateStore": "twinfleet.checker.store",
    "Step": "twinfleet.checker.transition",
    "System": "twinfleet.checker.system",
    "Transition": "twinfleet.checker.transition",
    "World": "twinfleet.checker.world",
    "bfs": "twinfleet.checker.search",
    "build_trace": "twinfleet.checker.trace",
    "check": "twinfleet.checker.driver",
    "dfs": "twinfleet.checker.search",
    "random_walk": "twinfleet.checker.search",
    "replay": "twinfleet.checker.trace",
}
__all__ = [
    "Action",
    "CheckOptions",
    "CheckResult",
    "CheckSettings",
    "CheckpointError",
    "Counterexample",
    "Crash",
    "Drop",
    "Event",
    "Failure",
    "Limits",
    "NondeterminismError",
    "Outcome",
    "PropertyError",
    "PropertySet",
    "PropertyViolation",
    "ReplayResult",
    "Rules",
    "RunEvent",
    "Search",
    "SearchStatistics",
    "Semantics",
    "StateStore",
    "Step",
    "System",
    "Transition",
    "World",
    "bfs",
    "build_trace",
    "check",
    "dfs",
    "random_walk",
    "replay",
]


def __getattr__(name: str) -> Any:
    """Load a public name from its module on first use (PEP 562)."""
    if name not in _HOMES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(_HOMES[name]), name)
    globals()[name] = value
    return value
