"""twinfleet's checker: explores every interleaving of the same node code the fleet runs.

Imports nothing from Zenoh or asyncio. Entry points: `check()` (scenario file →
`CheckResult`), `System` + `Search` for programmatic use, `replay()` for traces,
and `checker.commands.register` for the CLI.

Modules: `world` (worlds, events, identities), `semantics` (enabling rules),
`system` (successors; handler outcomes cached), `transition` (steps and what
they did), `faults` (optional `check:` settings: latency, deadlines, queue
bounds, drop/duplicate/crash faults), `store` (visited states: 64-bit digest
table, parents, edges), `graph` (paths, lassos), `search` (BFS/DFS/random),
`checkpoint` (save and resume a search), `properties`, `trace`, `check`,
`commands`.
"""

from twinfleet.checker.check import CheckOptions, CheckResult, check
from twinfleet.checker.checkpoint import CheckpointError
from twinfleet.checker.faults import CheckSettings
from twinfleet.checker.properties import PropertyError, PropertySet, Violation
from twinfleet.checker.search import (
    Limits,
    Outcome,
    Path,
    Search,
    SearchStatistics,
    bfs,
    dfs,
    random_walk,
)
from twinfleet.checker.semantics import Semantics
from twinfleet.checker.store import StateStore
from twinfleet.checker.system import Failure, Step, System, Transition
from twinfleet.checker.trace import NondeterminismError, ReplayResult, build_trace, replay
from twinfleet.checker.world import Event, World
from twinfleet.runtime.tracefile import TraceError

__all__ = [
    "CheckOptions",
    "CheckResult",
    "CheckSettings",
    "CheckpointError",
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
    "StateStore",
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
