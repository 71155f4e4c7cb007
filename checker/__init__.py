"""twinfleet's checker: explores every interleaving of the same node code the fleet runs.

Imports nothing from Zenoh or asyncio. Entry points: `check()` (scenario file →
`CheckResult`), `System` + `Search` for programmatic use, `replay()` for traces,
and `checker.commands.register` for the CLI.
"""

from checker.check import CheckOptions, CheckResult, check
from checker.properties import PropertyError, PropertySet, Violation
from checker.search import (
    Limits,
    Outcome,
    Path,
    Search,
    SearchStatistics,
    bfs,
    dfs,
    random_walk,
)
from checker.semantics import Semantics
from checker.system import Failure, Step, System, Transition
from checker.trace import NondeterminismError, ReplayResult, TraceError, build_trace, replay
from checker.world import Event, World

__all__ = [
    "CheckOptions",
    "CheckResult",
    "Event",
    "Failure",
    "Limits",
    "NondeterminismError",
    "Outcome",
    "Path",
    "PropertyError",
    "PropertySet",
    "ReplayResult",
    "Search",
    "SearchStatistics",
    "Semantics",
    "Step",
    "System",
    "TraceError",
    "Transition",
    "Violation",
    "World",
    "bfs",
    "build_trace",
    "check",
    "dfs",
    "random_walk",
    "replay",
]
