"""Which live time scale keeps timing faithful to the checker's logical time?

For one scenario (default C1a, fixed profile), run the fleet live at several
time scales and compare each robot's live arrival time, counted from its own
start (its first `planning` status), with the logical arrival time of the
same robot on a path of the checker (`robots.timing.predicted_arrivals`).
Prints one line per scale:

    scale  runs  mean |Δ| ms  max |Δ| ms  mean Δ ms  Δ spread ms  start spread ms  collisions ...

Δ > 0: live arrives later than the checker's logical time. "Δ spread" is,
per run, the largest minus the smallest Δ of its robots (averaged over the
runs): a drift common to every robot keeps their relative timing, a spread
changes which interleavings happen. "start spread" is the latest minus the
earliest robot start in fleet ms: the checker starts every node at t = 0.
Runs whose node was killed from outside the fleet are repeated.

    PYTHONPATH=. python benchmarks/agreement_timescale.py [--scenario launch/c1a.yaml]
        [--scales 1:2,2:3,5:3,10:3,20:3] [--json out/timescale.json]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from twinfleet.robots.live import live_run, private_copy  # noqa: E402
from twinfleet.robots.timing import arrival_errors, predicted_arrivals, summarise  # noqa: E402
from twinfleet.runtime.scenario.spec import load_scenario  # noqa: E402


def parse_scales(text: str) -> list[tuple[float, int]]:
    """"1:2,5:3" → [(1.0, 2), (5.0, 3)]."""
    out = []
    for item in text.split(","):
        scale, _, runs = item.partition(":")
        out.append((float(scale), int(runs or 3)))
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default=str(ROOT / "twinfleet" / "launch" / "c1a.yaml"))
    p.add_argument("--scales", default="1:2,2:3,5:3,10:3,20:3",
                   help="comma-separated SCALE:RUNS (default: %(default)s)")
    p.add_argument("--seed", type=int, default=1, help="seed of the first run at each scale")
    p.add_argument("--walks", type=int, default=5,
                   help="checker paths to compare with each other (default: %(default)s)")
    p.add_argument("--log", default=str(ROOT / "out" / "agreement_timescale.log"),
                   help="node output (default: %(default)s)")
    p.add_argument("--json", default=None, metavar="FILE", help="also write the figures as JSON")
    args = p.parse_args()

    scenario = private_copy(load_scenario(args.scenario), Path(args.log).parent / "scenarios")
    walks = [predicted_arrivals(args.scenario, seed=s) for s in range(args.walks)]
    predicted = walks[0].arrival_ms
    distinct = {tuple(sorted(w.arrival_ms.items())) for w in walks}
    print(f"# {scenario.name}: checker arrival times (ms, one path): {dict(predicted)}")
    print(f"# {len(distinct)} distinct arrival vector(s) over {args.walks} random checker paths")
    Path(args.log).parent.mkdir(parents=True, exist_ok=True)
    header = (f"{'scale':>5} {'runs':>4} {'mean |Δ| ms':>11} {'max |Δ| ms':>10} {'mean Δ ms':>9} "
              f"{'Δ spread ms':>11} {'start spread ms':>15} {'collisions':>10} {'passed':>6} "
              f"{'wall s/run':>10}")
    print(header)
    results = []
    with open(args.log, "w") as log:
        for scale, runs in parse_scales(args.scales):
            records = []
            k = 0
            while len(records) < runs:
                log.write(f"===== scale {scale:g} run {len(records) + 1}/{runs} =====\n")
                log.flush()
                record = asyncio.run(live_run(
                    scenario, time_scale=scale, seed=args.seed + len(records), out=log,
                    timeout_s=20 + 180 / scale, stop_on_collision=False))
                if record.interrupted:
                    return 130
                k += 1
                if record.killed_from_outside and k < 3 * runs:
                    print(f"# scale {scale:g}: {record.reason} (killed from outside); again",
                          flush=True)
                    continue
                records.append(record)
            errors = [arrival_errors(r.durations_ms, predicted) for r in records]
            drift = summarise(errors, len(records))
            spreads = [r.start_spread_ms for r in records if r.start_spread_ms is not None]
            gaps = [max(e.values()) - min(e.values()) for e in errors if e]
            line = {
                "scale": scale, "runs": len(records), "mean_abs_ms": round(drift.mean_abs_ms, 1),
                "max_abs_ms": drift.max_abs_ms, "mean_signed_ms": round(drift.mean_signed_ms, 1),
                "delta_spread_ms": round(statistics.mean(gaps), 1) if gaps else None,
                "start_spread_ms": round(statistics.mean(spreads), 1) if spreads else None,
                "collision_runs": sum(bool(r.collisions) for r in records),
                "passed": sum(r.passed for r in records),
                "wall_s": round(statistics.mean(r.wall_s for r in records), 2),
                "errors_ms": errors,
            }
            results.append(line)
            print(f"{scale:>5g} {line['runs']:>4} {line['mean_abs_ms']:>11} "
                  f"{line['max_abs_ms']:>10} {line['mean_signed_ms']:>9} "
                  f"{line['delta_spread_ms']!s:>11} {line['start_spread_ms']!s:>15} {line['collision_runs']:>10} "
                  f"{line['passed']:>6} {line['wall_s']:>10}", flush=True)
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps({
            "scenario": args.scenario, "predicted_ms": dict(predicted),
            "distinct_checker_vectors": len(distinct), "date": time.strftime("%Y-%m-%d"),
            "results": results}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
