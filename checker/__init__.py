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
parents, edges), `graph` (paths, lassos), `outcome` (limits, statistics,
counterexamples, verdicts), `search` (BFS/DFS), `walks` (random walks),
`checkpoint` (save and resume a search), `properties`, `trace`, `check`,
`commands`.
"""

from twinfleet.checker.check import CheckOptions, CheckResult, check
from twinfleet.checker.checkpoint import CheckpointError
from twinfleet.checker.faults import CheckSettings
from twinfleet.checker.outcome import Counterexample, Limits, Outcome, SearchStatistics
from twinfleet.checker.properties import PropertyError, PropertySet, PropertyViolation
from twinfleet.checker.search import Search, bfs, dfs, random_walk
from twinfleet.checker.semantics import Rules, Semantics
from twinfleet.checker.store import StateStore
from twinfleet.checker.system import System
from twinfleet.checker.trace import NondeterminismError, ReplayResult, build_trace, replay
from twinfleet.checker.transition import Action, Crash, Drop, Failure, RunEvent, Step, Transition
from twinfleet.checker.world import Event, World
from twinfleet.runtime.tracefile import TraceError

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
    "TraceError",
    "Transition",
    "World",
    "bfs",
    "build_trace",
    "check",
    "dfs",
    "random_walk",
    "replay",
]
