"""Cost of the live verdict's state reports on C1a: the same fleet with and without them.

Each pair runs the shipped C1a scenario twice in this process (`run_fleet`, an
embedded router and six node processes over Zenoh on loopback), once with the
live monitor (every node publishes a state report after each handler that
changed its state; the launcher evaluates the properties) and once without
(``judge=False``), alternating which goes first. Measured per run: CPU
seconds of the node processes (`RUSAGE_CHILDREN`, they are reaped inside the
run), CPU seconds of the launcher (`RUSAGE_SELF`: the monitor's decoding and
evaluation), wall seconds, state reports received, and r5's arrival (fleet s;
the slowest robot, as a check that the reports do not change what the fleet
does). Ratios are with/without, medians over the pairs. The two runs of a pair
differ only in the reports, so the ratio is what they cost.

    python benchmarks/live_state_reports.py                # 3 pairs at --time-scale 5 (~1 min)
    python benchmarks/live_state_reports.py --pairs 1      # ~20 s
"""

from __future__ import annotations

import argparse
import asyncio
import io
import json
import resource
import statistics
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from twinfleet.runtime.fleet.launcher import LaunchOptions, run_fleet  # noqa: E402
from twinfleet.runtime.scenario.spec import load_scenario  # noqa: E402


def _cpu(who: int) -> float:
    usage = resource.getrusage(who)
    return usage.ru_utime + usage.ru_stime


def one_run(scenario_path: str, time_scale: float, monitor: bool) -> dict[str, Any]:
    """Run C1a once; its costs and outcome."""
    scenario = load_scenario(scenario_path)
    children, own, wall = (_cpu(resource.RUSAGE_CHILDREN), _cpu(resource.RUSAGE_SELF),
                           time.monotonic())
    options = LaunchOptions(time_scale=time_scale, timeout_s=120, handle_signals=False,
                            judge=monitor)
    result = asyncio.run(run_fleet(scenario, options, out=io.StringIO()))
    report = result.report
    r5 = report.records["r5"].arrival_ms if report is not None else None
    return {"nodes_cpu_s": _cpu(resource.RUSAGE_CHILDREN) - children,
            "launcher_cpu_s": _cpu(resource.RUSAGE_SELF) - own,
            "wall_s": time.monotonic() - wall, "reports": result.state_reports,
            "r5_arrival_s": (r5 or 0) / 1000, "passed": result.passed,
            "verdict": result.verdict.lines()[0] if result.verdict is not None else "-"}


def main() -> None:
    """Run the pairs, print one line per run, the ratios and a JSON summary."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--pairs", type=int, default=3, help="runs with and without (default 3)")
    p.add_argument("--time-scale", type=float, default=5.0, help="fleet speed-up (default 5)")
    p.add_argument("--scenario", default="c1a", help="scenario (default: the shipped c1a)")
    args = p.parse_args()
    runs: dict[bool, list[dict[str, Any]]] = {True: [], False: []}
    for pair in range(args.pairs):
        for monitor in ((True, False) if pair % 2 == 0 else (False, True)):
            r = one_run(args.scenario, args.time_scale, monitor)
            runs[monitor].append(r)
            print(f"pair {pair + 1} {'with   ' if monitor else 'without'} reports: "
                  f"nodes CPU {r['nodes_cpu_s']:.2f} s, launcher CPU {r['launcher_cpu_s']:.2f} s, "
                  f"wall {r['wall_s']:.1f} s, {r['reports']} reports, "
                  f"r5 arrived at {r['r5_arrival_s']:.2f} s; {r['verdict']}", flush=True)

    def ratio(key: str) -> float:
        return statistics.median(w[key] / o[key] for w, o in zip(runs[True], runs[False],
                                                                 strict=True) if o[key])

    def total(r: dict[str, Any]) -> float:
        return r["nodes_cpu_s"] + r["launcher_cpu_s"]

    summary = {"pairs": args.pairs, "time_scale": args.time_scale,
               "nodes_cpu_ratio": round(ratio("nodes_cpu_s"), 3),
               "launcher_cpu_ratio": round(ratio("launcher_cpu_s"), 3),
               "total_cpu_ratio": round(statistics.median(
                   total(w) / total(o) for w, o in zip(runs[True], runs[False], strict=True)), 3),
               "wall_ratio": round(ratio("wall_s"), 3),
               "reports_per_run": statistics.median(r["reports"] for r in runs[True]),
               "all_passed": all(r["passed"] for rs in runs.values() for r in rs)}
    print(f"state reports on {args.scenario}: node CPU x{summary['nodes_cpu_ratio']}, launcher CPU "
          f"x{summary['launcher_cpu_ratio']}, total CPU x{summary['total_cpu_ratio']}, wall "
          f"x{summary['wall_ratio']} (with / without, median of {args.pairs} pairs)")
    print(json.dumps({"summary": summary}))


if __name__ == "__main__":
    main()
