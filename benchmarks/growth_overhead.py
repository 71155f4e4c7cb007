"""What the state-growth diagnosis (`checker.growth`) costs a search that finishes.

Every search samples one new world in 16 for `GrowthWatch`. This script runs, in one
process and alternating, each scenario's full check (its default reduction, BFS to
the end) with the watch on and with `GrowthWatch.observe` replaced by a no-op (the
sampling test itself stays: one `&` per new world), `--repeat` rounds. It prints per
round the CPU seconds of both (`time.process_time`: less disturbed than wall time on
a shared machine, still noisy) and their ratio, and, measured inside the "on" run,
the CPU time spent in `observe` and `notes` as a share of that run: the direct
figure, which a shared machine disturbs far less. Then the median and spread of
both. Defaults: `launch/c1a.yaml` (5,516 states, reduced to one long path) and
`launch/c1a_rebeca.yaml` (18,527 states, unreduced, wide).

    python3 benchmarks/growth_overhead.py [SCENARIO ...] [--repeat 5]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from twinfleet.checker.driver import CheckOptions, check  # noqa: E402
from twinfleet.checker.growth import GrowthWatch  # noqa: E402

DEFAULT = [str(ROOT / "twinfleet" / "launch" / n) for n in ("c1a.yaml", "c1a_rebeca.yaml")]


def _timed(scenario: str) -> tuple[float, int]:
    started = time.process_time()
    result = check(scenario, CheckOptions(trace_out=None))
    return time.process_time() - started, result.statistics.states


class _Clock:
    """CPU seconds spent in the watch's own methods."""

    def __init__(self) -> None:
        self.spent = 0.0

    def wrap(self, method: Callable[..., Any]) -> Callable[..., Any]:
        def timed(*args: Any) -> Any:
            started = time.process_time()
            try:
                return method(*args)
            finally:
                self.spent += time.process_time() - started
        return timed


def _with_clock(run: Callable[[], tuple[float, int]]) -> tuple[float, int, float]:
    clock = _Clock()
    observe, notes = GrowthWatch.observe, GrowthWatch.notes
    GrowthWatch.observe = clock.wrap(observe)  # type: ignore[method-assign]
    GrowthWatch.notes = clock.wrap(notes)  # type: ignore[method-assign]
    try:
        seconds, states = run()
    finally:
        GrowthWatch.observe, GrowthWatch.notes = observe, notes  # type: ignore[method-assign]
    return seconds, states, clock.spent


def _without_watch(run: Callable[[], tuple[float, int]]) -> tuple[float, int]:
    observe = GrowthWatch.observe

    def nothing(self: Any, parent: Any, t: Any) -> None:
        return None

    GrowthWatch.observe = nothing  # type: ignore[method-assign]
    try:
        return run()
    finally:
        GrowthWatch.observe = observe  # type: ignore[method-assign]


def main(argv: Sequence[str] | None = None) -> int:
    """Run the comparison and print it."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenarios", nargs="*", default=DEFAULT)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args(argv)
    for scenario in args.scenarios:
        _timed(scenario)  # warm up: imports, caches of the node modules
        ratios, shares = [], []
        for k in range(args.repeat):
            off, states = _without_watch(lambda s=scenario: _timed(s))
            on, states_on, spent = _with_clock(lambda s=scenario: _timed(s))
            assert states == states_on
            ratios.append(on / off)
            shares.append(spent / on)
            print(f"{Path(scenario).name} round {k + 1}: {states:,} states, watch off "
                  f"{off:.2f} s, on {on:.2f} s, ratio {on / off:.3f}; in the watch "
                  f"{spent * 1000:.0f} ms = {100 * spent / on:.2f} %", flush=True)
        print(f"{Path(scenario).name}: ratio on/off median {statistics.median(ratios):.3f} "
              f"(min {min(ratios):.3f}, max {max(ratios):.3f}); share in the watch median "
              f"{100 * statistics.median(shares):.2f} % (min {100 * min(shares):.2f}, max "
              f"{100 * max(shares):.2f}) over {args.repeat} rounds")
    return 0


if __name__ == "__main__":
    sys.exit(main())
