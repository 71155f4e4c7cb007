"""What the default node-contract checks cost (`checker.diagnosis`): check with and without them.

    python3 benchmarks/checker_contract.py [SCENARIO ...] [--rounds N]

For each scenario (default: c1a and c1a_rebeca) the search runs `rounds` times
each way, alternating, and prints one JSON line: the median search time with
the checks (`verify`) and without, their ratio, and the handler runs each way
(with the checks every new handler run runs twice, cache hits not at all).
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

from twinfleet.checker import System, check
from twinfleet.checker.driver import CheckOptions, load
from twinfleet.checker.properties import PropertySet
from twinfleet.checker.search import Search


def _timed(scenario: str, verify: bool) -> tuple[float, int, int, str]:
    started = time.perf_counter()
    result = check(scenario, CheckOptions(verify=verify, trace_out=None))
    return time.perf_counter() - started, result.statistics.states, \
        result.statistics.transitions, result.status


def _runs(scenario: str, verify: bool) -> tuple[int, int]:
    """Handler runs (re-executions included) and re-executions of one search."""
    loaded = load(scenario)
    props = PropertySet.from_scenario(loaded)
    system = System(loaded, properties=props, verify=verify)
    Search(system, props).run("bfs")
    return system.runner.handler_runs, system.runner.reruns


def measure(scenario: str, rounds: int) -> dict[str, object]:
    """Median times with and without the checks, and the handler runs each way."""
    times: dict[bool, list[float]] = {True: [], False: []}
    counts = None
    for _ in range(rounds):
        for verify in (False, True):
            dt, states, transitions, status = _timed(scenario, verify)
            times[verify].append(dt)
            counts = (states, transitions, status)
    with_checks, without = statistics.median(times[True]), statistics.median(times[False])
    runs_on, reruns = _runs(scenario, True)
    runs_off, _ = _runs(scenario, False)
    assert counts is not None
    return {"scenario": scenario, "verdict": counts[2], "states": counts[0],
            "transitions": counts[1], "rounds": rounds,
            "median_s_without_checks": round(without, 3),
            "median_s_with_checks": round(with_checks, 3),
            "ratio": round(with_checks / without, 3),
            "handler_runs_without": runs_off, "handler_runs_with": runs_on,
            "reexecutions": reruns}


def main() -> None:
    """Print one JSON line per scenario."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenarios", nargs="*", default=["c1a", "c1a_rebeca"])
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    for scenario in args.scenarios:
        print(json.dumps(measure(scenario, args.rounds)), flush=True)


if __name__ == "__main__":
    main()
