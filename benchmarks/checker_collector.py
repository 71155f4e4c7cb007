"""What the garbage collector's thresholds cost a search (`twinfleet.checker.collector`).

The same search, alternately with CPython's default thresholds and with the search's
(`SEARCH_THRESHOLDS`), for `--max-time` seconds each: transitions/s, the full
collections made, and the ratio of the medians. Cases: C1a with 0-1 ms of latency
reduced (the wide search of docs/distributed.md; it restarts once after walking ahead,
so "last attempt" gives the rate since then) and six robots in lanes, unreduced.

    python benchmarks/checker_collector.py [--cases c1a_jitter_por,lanes6] [--max-time 30]
        [--rounds 2]
"""

from __future__ import annotations

import argparse
import gc
import statistics
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "benchmarks")]

from checker_distributed import cases  # noqa: E402

from twinfleet.checker import CheckOptions, check, collector  # noqa: E402

SEARCH = collector.SEARCH_THRESHOLDS


def one(path: Path, reduction: str, max_time: float, thresholds: tuple[int, ...]
        ) -> tuple[float, float, int]:
    """(transitions/s, the last attempt's, full collections) of one search."""
    collector.SEARCH_THRESHOLDS = thresholds  # read by `seldom_collections` at each check
    full = gc.get_stats()[2]["collections"]
    s = check(path, CheckOptions(reduction=reduction, max_time_s=max_time)).statistics
    last = s.attempt_transitions_per_s if s.attempt_s is not None else s.transitions_per_s
    return s.transitions_per_s, last, gc.get_stats()[2]["collections"] - full


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--cases", default="c1a_jitter_por,lanes6", help="comma-separated cases")
    p.add_argument("--max-time", type=float, default=30.0, help="seconds per search")
    p.add_argument("--rounds", type=int, default=2, help="searches each way, alternated")
    args = p.parse_args()
    default = gc.get_threshold()
    with tempfile.TemporaryDirectory() as tmp:
        for case, path, reduction in cases(args.cases, Path(tmp)):
            runs: dict[tuple[int, ...], list[tuple[float, float, int]]] = {default: [],
                                                                           SEARCH: []}
            for _ in range(args.rounds):
                for thresholds in runs:
                    runs[thresholds].append(one(path, reduction, args.max_time, thresholds))
            print(f"{case} (reduction {reduction}, up to {args.max_time:g} s per search):")
            for thresholds, found in runs.items():
                rate = statistics.median(r[0] for r in found)
                last = statistics.median(r[1] for r in found)
                full = statistics.median(r[2] for r in found)
                print(f"  thresholds {thresholds!s:<16} {rate:>9,.0f} tr/s  last attempt "
                      f"{last:>9,.0f} tr/s  full collections {full:.0f}")
            base = statistics.median(r[1] for r in runs[default])
            ours = statistics.median(r[1] for r in runs[SEARCH])
            print(f"  search thresholds / default: x{ours / base:.2f} (last attempt)",
                  flush=True)
    collector.SEARCH_THRESHOLDS = SEARCH


if __name__ == "__main__":
    main()
