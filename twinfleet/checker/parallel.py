"""Where independent simulations run: the seam between statistical checking and an engine.

`run_simulations(batch_fn, indices, workers)` runs `batch_fn` over contiguous
slices of `indices` and returns every result in index order, whoever ran it:
the caller aggregates in index order, so its answers do not depend on the
number of workers. `batch_fn` must be picklable for more than one worker (a
module-level callable object, such as `checker.statistical.SimulationJob`,
that builds what it needs in the process that first calls it).

Engines: `workers <= 1` runs in this process; more runs a
`concurrent.futures.ProcessPoolExecutor` kept for the whole command
(`ProcessEngine`), whose processes come from a fork server: a plain fork
copies the caller's threads' locks as they are (an experiment forks after
its live fleets have run Zenoh threads here), and a copied lock that was
held is held for ever in the child. With a cluster address, `checker.cluster.engine.RayEngine`
sends each slice to the Ray cluster as a task and returns the slices' results
in the order given (`check --statistical --workers N --cluster ADDRESS`).
"""

from __future__ import annotations

import multiprocessing
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from typing import Protocol, TypeVar, final

R = TypeVar("R")
BatchFn = Callable[[list[int]], list[R]]


class Engine(Protocol):
    """Runs batches of simulations; results per batch, in the order the batches were given."""

    workers: int

    def map(self, batch_fn: BatchFn[R], batches: Sequence[list[int]]) -> list[list[R]]:
        """`batch_fn` applied to every batch."""
        ...

    def close(self) -> None:
        """Release the engine's workers."""
        ...


@final
class InProcess:
    """Every batch in this process, one after another."""

    workers = 1

    def map(self, batch_fn: BatchFn[R], batches: Sequence[list[int]]) -> list[list[R]]:
        """`batch_fn` applied to every batch, here."""
        return [batch_fn(b) for b in batches]

    def close(self) -> None:
        """Nothing to release."""


@final
class ProcessEngine:
    """Batches spread over `workers` local processes (kept until `close`)."""

    def __init__(self, workers: int) -> None:
        self.workers = workers
        self._pool = ProcessPoolExecutor(max_workers=workers,
                                         mp_context=multiprocessing.get_context("forkserver"))

    def map(self, batch_fn: BatchFn[R], batches: Sequence[list[int]]) -> list[list[R]]:
        """`batch_fn` applied to every batch in the pool; results in batch order."""
        return list(self._pool.map(batch_fn, batches))

    def close(self) -> None:
        """Stop the worker processes."""
        self._pool.shutdown(cancel_futures=True)


def engine_for(workers: int, cluster: str | None = None) -> Engine:
    """The engine for `workers` local workers (1: this process), or `workers` Ray tasks at a
    time on the Ray cluster at `cluster` ("local": one started here; a Ray already
    initialised in this process is used as it is)."""
    if cluster is not None:
        from twinfleet.checker.cluster import engine_module

        engine: Engine = engine_module(cluster == "local").RayEngine(workers, None if cluster == "local"
                                                   else cluster)
        return engine
    return InProcess() if workers <= 1 else ProcessEngine(workers)


def split(indices: Sequence[int], parts: int) -> list[list[int]]:
    """`indices` cut into at most `parts` contiguous, nearly equal slices."""
    parts = max(1, min(parts, len(indices)))
    size, extra = divmod(len(indices), parts)
    out, start = [], 0
    for k in range(parts):
        end = start + size + (1 if k < extra else 0)
        out.append(list(indices[start:end]))
        start = end
    return [b for b in out if b]


def run_simulations(batch_fn: BatchFn[R], indices: Sequence[int], workers: int | Engine,
                    ) -> list[R]:
    """Every result of `batch_fn` over `indices`, in index order (module docstring);
    `workers` is a count (an engine is made and closed) or an engine kept by the caller."""
    engine = engine_for(workers) if isinstance(workers, int) else workers
    try:
        return [r for batch in engine.map(batch_fn, split(indices, engine.workers))
                for r in batch]
    finally:
        if isinstance(workers, int):
            engine.close()
