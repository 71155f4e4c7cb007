"""Running a sweep: every point not in the cache on an engine, results as they finish.

The engine is the checker's (`checker.parallel.engine_for`): this process, local worker
processes, or Ray tasks. Its `map` answers a whole list of batches at once, so the sweep
gives it one point per call from as many threads as the engine has workers: a point's
result is cached and reported the moment it is known, and a slow point holds up no
other (batches of several points would wait for their slowest). The threads only wait;
the checks run in the engine's processes.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from dataclasses import dataclass
from typing import final

from twinfleet.checker.parallel import Engine
from twinfleet.sweep.cache import PointCache, point_key, scenario_digest
from twinfleet.sweep.grid import Point, point_label
from twinfleet.sweep.point import PointResult, SweepSettings, run_point


@final
@dataclass(frozen=True)
class PointJob:
    """The engine's batch function: grid indices → their results (picklable, so a worker
    process or a Ray task can run it)."""

    settings: SweepSettings
    points: tuple[Point, ...]
    names: tuple[str, ...]  # each point's trace file name (`trace_name`)

    def __call__(self, indices: list[int]) -> list[PointResult]:
        """Check the points at `indices`, one after another."""
        return [run_point(self.settings, self.points[i], self.names[i]) for i in indices]


@final
@dataclass(frozen=True)
class Finished:
    """One point's result as the sweep learns it (what a progress line shows)."""

    index: int  # in the grid's order
    done: int  # points known so far, this one included
    total: int
    result: PointResult
    cached: bool  # read from the cache, not run now


Report = Callable[[Finished], None]


def run_sweep(settings: SweepSettings, grid: Sequence[Point], engine: Engine,
              cache: PointCache | None = None, report: Report | None = None,
              ) -> list[PointResult]:
    """Every point's result, in the grid's order: cached points are read, the others run on
    `engine` and cached as each finishes (so a stopped sweep loses only running points).

    Raises:
        KeyboardInterrupt: Ctrl-C; the points finished so far are in the cache.
    """
    digest = scenario_digest(settings.scenario)
    keys = tuple(point_key(digest, settings, p) for p in grid)
    results: dict[int, PointResult] = {}

    def finish(index: int, result: PointResult, cached: bool) -> None:
        results[index] = result
        if cache is not None and not cached:
            cache.put(keys[index], result)
        if report is not None:
            report(Finished(index, len(results), len(grid), result, cached))

    for index, key in enumerate(keys):
        stored = None if cache is None else cache.get(key)
        if stored is not None:
            finish(index, stored, cached=True)
    todo = [i for i in range(len(grid)) if i not in results]
    job = PointJob(settings, tuple(grid), tuple(trace_name(p, k) for p, k in zip(grid, keys,
                                                                                   strict=True)))
    if engine.workers <= 1:  # here, in the main thread: Ctrl-C stops the check cleanly
        for index in todo:
            finish(index, engine.map(job, [[index]])[0][0], cached=False)
    else:
        _run_threads(job, todo, engine, finish)
    return [results[i] for i in range(len(grid))]


def trace_name(point: Point, key: str) -> str:
    """``r4.speed=0.8_scan_rate_ms=60-1a2b3c4d``: a point's trace file name, readable, safe
    on any file system, and told apart by its cache key from the same point under other
    settings."""
    return re.sub(r"[^\w.=+-]+", "_", point_label(point)).strip("_")[:120] + f"-{key[:8]}"


def _run_threads(job: PointJob, todo: Sequence[int], engine: Engine,
                 finish: Callable[[int, PointResult, bool], None]) -> None:
    """`todo` on `engine`, `engine.workers` points at a time, each finished as it ends."""
    with ThreadPoolExecutor(max_workers=engine.workers, thread_name_prefix="sweep") as threads:
        running: dict[Future[list[list[PointResult]]], int] = {
            threads.submit(engine.map, job, [[i]]): i for i in todo}
        try:
            while running:
                done, _ = wait(running, return_when=FIRST_COMPLETED)
                # in the grid's order when several end together
                for future in sorted(done, key=running.__getitem__):
                    finish(running.pop(future), future.result()[0][0], False)
        except BaseException:
            for future in running:  # points not started yet stay unstarted
                future.cancel()
            # the points still running are lost (they run again on resume); closing the
            # engine here, not in the caller, lets the threads waiting on them end
            engine.close()
            raise
