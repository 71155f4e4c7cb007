"""The search on several processes or machines (Ray), behind the checker's seams.

`distributed(...)` runs a check's search as a strict BFS over worker and
shard actors (`checker.cluster.coordinator`, design in docs/distributed.md),
reduced or not, or in a relaxed order on workers that do not wait for each
other (`checker.cluster.flow`), with `eventually` properties decided on the
graph gathered to the coordinator, and returns its `Outcome` with a line for the summary;
`why_local` says when a search must run in one process instead (random
walks). A distributed search
saves itself to a checkpoint file and continues one on any number of workers
(`Checkpointing`, `is_distributed_checkpoint`). Only
`checker.cluster.engine` imports Ray, and only when a search first gets wide
enough to need it.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from contextlib import ExitStack
from dataclasses import dataclass
from typing import Any, cast, final

from twinfleet.checker.cluster.backend import Backend, Checkpointing, Traffic
from twinfleet.checker.cluster.coordinator import ENGINE, START_STATES, Coordinator
from twinfleet.checker.cluster.flow import FlowBackend
from twinfleet.checker.cluster.spec import ClusterError, SystemSpec, fingerprint
from twinfleet.checker.cluster.starting import engine_module, start
from twinfleet.checker.outcome import Limits, Outcome
from twinfleet.checker.properties import PropertySet
from twinfleet.checker.reduction import Reduction
from twinfleet.checker.system import System
from twinfleet.runtime.contract.kinds import Status

__all__ = ["Checkpointing", "ClusterError", "Distributed", "SystemSpec", "distributed",
           "engine_module", "is_distributed_checkpoint", "why_local"]


@final
@dataclass
class Distributed:
    """A distributed search's outcome, its summary line and what crossed processes."""

    outcome: Outcome
    note: str
    traffic: Traffic


def why_local(strategy: str) -> str | None:
    """Why this search runs in one process even though workers were asked for, or None."""
    if strategy == "random":
        return "random walks run in one process"
    return None


def is_distributed_checkpoint(meta: Mapping[str, Any]) -> bool:
    """Whether a checkpoint's meta says the distributed search wrote it."""
    return meta.get("engine") == ENGINE


def distributed(system: System, properties: PropertySet, limits: Limits, spec: SystemSpec, *,
                workers: int, address: str | None, min_width: int,
                report: Callable[[str], None] | None = None,
                on_backend: Callable[[Backend], None] | None = None,
                checkpointing: Checkpointing | None = None,
                resume: Mapping[str, Any] | None = None,
                reduction: Reduction | None = None, relaxed: bool = False) -> Distributed:
    """Search on `workers` Ray workers once the frontier is `min_width` wide (module
    docstring), from the checkpoint `resume` if given (one local worker: in this process);
    `relaxed`: in a relaxed order there (a search without reduction, depth bound or
    checkpoints). ClusterError when the cluster cannot start or loses a worker."""
    expected = fingerprint(system)
    with ExitStack() as stack:
        def starting(width: int, make: Callable[[Any], Any]) -> Any:
            if report is not None:
                report(f"[check] frontier {width:,} wide: starting {workers} Ray worker(s)"
                       + (" (relaxed order)" if relaxed else "")
                       + ("" if min_width <= 1 else "; the search goes on here until they "
                          "are up"))
            return start(workers, make, address, stack.callback, background=min_width > 1)

        def made(engine: Any) -> Backend:
            backend: Backend = engine.RayBackend(spec, expected, workers)
            if on_backend is not None:
                on_backend(backend)
            return backend

        def factory(width: int) -> Backend:
            return cast(Backend, starting(width, made))

        def flow(width: int) -> FlowBackend:
            return cast(FlowBackend, starting(
                width, lambda engine: engine.RayFlow(spec, expected, workers)))

        here = workers == 1 and address is None
        coordinator = Coordinator(system, properties, limits, None if here else factory,
                                  min_width, report, checkpointing=checkpointing,
                                  reduction=reduction,
                                  flow=flow if relaxed and not here else None,
                                  start_states=START_STATES if min_width > 1 else 0)
        if resume is not None:
            coordinator.restore(resume)
        outcome = coordinator.run()
    return Distributed(outcome, _note(coordinator, outcome, workers, min_width, here),
                       coordinator.traffic)


def _note(coordinator: Coordinator, outcome: Outcome, workers: int, min_width: int,
          here: bool) -> str:
    """The summary's line on where and in which order the search ran."""
    t, place, reduction = coordinator.traffic, coordinator.place, coordinator.reduction
    if here:
        note = "strict BFS in one process (the distributed search's order and checkpoints)"
    elif place.started_at is not None and place.distributed_at is None:
        note = (f"ran in one process: the Ray workers started at depth "
                f"{place.started_at} were not up before the search ended or narrowed")
    elif place.distributed_at is None and reduction is not None and reduction.waiting and \
            reduction.aside is None:
        note = (f"ran in one process: por waits until {reduction.reduce_from:,} worlds are "
                "stored to decide, on a sample of the frontier here, whether to reduce, and "
                "this search stored fewer")
    elif place.distributed_at is None and outcome.statistics.states < START_STATES:
        note = (f"ran in one process: {outcome.statistics.states:,} states, under the "
                f"{START_STATES:,} at which Ray's workers start (a smaller search is over "
                "before they would be up)")
    elif place.distributed_at is None:
        note = (f"ran in one process: no level held {min_width} worlds (--min-width) after "
                f"the first {START_STATES:,} states")
    else:
        per = t.claims / max(1, outcome.statistics.states)
        runs = coordinator.system.runner.handler_runs + sum(t.handler_runs)
        order = "relaxed order" if place.flow is not None else "strict BFS"
        levels = "" if place.flow is not None else f"{t.levels} levels, "
        note = (f"{order} on {workers} Ray worker(s) from depth "
                f"{place.distributed_at} ({levels}{per:.2f} claims per "
                f"state, {t.stolen:,} worlds moved in {t.moves} blobs, {runs:,} handler runs"
                + (f", back in this process {t.returns} time(s) when it narrowed" if t.returns
                   else "") + ")")
        if place.flow is not None:
            note += ("; the states and transitions of a strict BFS, depth and counterexample "
                     "as found (--search bfs: the shortest)")
    eventually = {p.name for p in coordinator.properties.eventually}
    violated = outcome.violation.property if outcome.violation is not None else None
    if eventually and (outcome.status is Status.HOLDS or violated in eventually):
        note += "; eventually properties: lasso search on the graph gathered to this process"
    return note
