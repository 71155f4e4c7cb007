"""Statistical checking speed: C1a before and after the engine's speed-ups, simulations per
second per worker for every paper case, and the time c2a takes to a 95 % interval of
half-width <= 0.05 on 2 workers.

Part 0 runs `twinfleet check c1a --statistical` (the command's own engine and workers, the
shipped loopback model, 120 s of fleet time per simulation) with the code of git revision
`--before` (default 3ae704d, the engine before the speed-ups of issue 40; extracted with `git
archive` into a temporary directory, run in a subprocess) and with this checkout, side by
side in one run: `--rate-simulations` simulations on 1 worker, then 400 (`--estimate`) on
`--workers` workers. It prints simulations/s of each, after / before, and whether the
estimates of the 400 agree: each property's count after inside the 95 % interval before,
and the same properties violated in every simulation.

Part 1 runs `--simulations N` simulations of each case (C1a-C1c and C2a-C2c in the fixed
profile, C2a-C2c in the rebeca profile) in this process, one worker, as `twinfleet check
CASE --statistical` does by default (the loopback timing model, the scenario's `live.timeout_s`
as horizon, node-contract checks on), and prints simulations/s, steps/s and how the
simulations ended. "vs c2a" is each case's rate over c2a's, measured in the same run. Then
c2a once more with every handler run (`Simulator(reuse=False)`: the simulation path before
handler runs were kept across steps and simulations, `Runner.run_drawn`): the speed-up of
keeping them, and a check that both give the same simulations.

Part 2 runs `twinfleet check c2a --statistical --precision 0.05 --confidence 0.95 --workers 2`
(`--no-contract-checks` with the flag of the same name) and prints the simulations and wall
time it took, and that time over the 10-minute target.

    PYTHONPATH=. python benchmarks/statistical_throughput.py [--simulations 8]
        [--cases c1a,c2a] [--workers 2] [--no-contract-checks] [--skip-precision]
        [--before REV] [--rate-simulations 32] [--estimate 400] [--only-speedup]

The machine's other load changes the figures: run it on an otherwise idle machine, or read
the ratios.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

from twinfleet.checker.driver import load
from twinfleet.checker.simulate import Simulation, Simulator
from twinfleet.checker.statistical import StatisticalOptions, check_statistical, timed_system
from twinfleet.checker.timing import default_timing

ROOT = Path(__file__).resolve().parents[1]
CASES = ("c1a", "c1b", "c1c", "c2a", "c2b", "c2c", "c2a_rebeca", "c2b_rebeca", "c2c_rebeca")
TARGET_S = 600.0


def throughput(case: str, simulations: int, verify: bool, reuse: bool = True,
               ) -> tuple[float, float, str, list[Simulation]]:
    """(simulations/s, steps/s, how they ended, the simulations) of `simulations`
    simulations of `case`, in this process."""
    spec = load(ROOT / "twinfleet" / "launch" / f"{case}.yaml")
    model = default_timing()
    system, props = timed_system(spec, model, verify=verify)
    sim = Simulator(system, props, model, seed=spec.seed, reuse=reuse,
                    horizon_ms=int(1000 * (spec.live.timeout_s or 60)), max_steps=1_000_000)
    start = time.perf_counter()
    done = [sim.run(i) for i in range(simulations)]
    elapsed = time.perf_counter() - start
    steps = sum(s.steps for s in done)
    ends = Counter(s.ended for s in done)
    violated = sum(1 for s in done if s.violated)
    how = ", ".join(f"{n} {why}" for why, n in ends.most_common()) + f"; {violated} violating"
    return simulations / elapsed, steps / elapsed, how, done


def _same(a: list[Simulation], b: list[Simulation]) -> bool:
    return [(s.violated, s.steps, s.end_ms, s.ended, s.first) for s in a] == [
        (s.violated, s.steps, s.end_ms, s.ended, s.first) for s in b]


# Run in a subprocess with one tree's code first on the path: c1a's simulations on W
# workers, as JSON (wall s, simulations, per-simulation violated properties, estimates).
# The CPU time of the worker processes is read from /proc (Linux) after each round, while
# they live: the descendants of this process, each one's latest utime + stime.
_MEASURE = """
import json, os, sys, tempfile, time, twinfleet
from twinfleet.checker.statistical import StatisticalOptions, check_statistical
assert twinfleet.__file__.startswith(sys.argv[1]), twinfleet.__file__
TICK = os.sysconf("SC_CLK_TCK")
workers = {}
def descendants():
    parent = {}
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            stat = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        parent[int(pid)] = (int(stat[1]), (int(stat[11]) + int(stat[12])) / TICK)
    mine, grew = {os.getpid()}, True
    while grew:
        new = {p for p, (pp, _) in parent.items() if pp in mine} - mine
        mine |= new
        grew = bool(new)
    return {p: parent[p][1] for p in mine - {os.getpid()}}
def progress(result):
    workers.update(descendants())
cpu = time.process_time()
with tempfile.TemporaryDirectory() as out:
    r = check_statistical(sys.argv[1] + f"/twinfleet/launch/{sys.argv[4]}.yaml",
        StatisticalOptions(simulations=int(sys.argv[2]), workers=int(sys.argv[3]),
                           traces_out=out, max_traces=0, progress=progress))
print(json.dumps({"wall": r.elapsed_s, "n": len(r.simulations),
                  "cpu": time.process_time() - cpu + sum(workers.values()),
                  "violated": [list(s.violated) for s in r.simulations],
                  "estimates": [[e.name, e.violations, e.n, e.low, e.high]
                                for e in r.estimates()]}))
"""


def _measure(tree: Path, simulations: int, workers: int, case: str) -> dict[str, object]:
    """One side's run; "cpu": the CPU s of the command's process and of its worker
    processes (which a machine shared with other work inflates less than the wall time;
    both include importing twinfleet and building the System)."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    done = subprocess.run([sys.executable, "-c", _MEASURE, str(tree), str(simulations),
                           str(workers), case], env=env, cwd=tree,  # `-c` puts the cwd first
                          capture_output=True, text=True, check=False)
    if done.returncode:
        raise SystemExit(f"{tree}: the measurement failed: {done.stderr.strip()[-2000:]}")
    result: dict[str, object] = json.loads(done.stdout.splitlines()[-1])
    return result


def _agree(before: dict[str, object], after: dict[str, object]) -> str:
    """Whether each count after lies in the interval before, and the simulations agree."""
    old = {e[0]: e for e in before["estimates"]}  # type: ignore[attr-defined]
    inside = all(old[name][3] <= k / n <= old[name][4] if name in old else k == 0
                 for name, k, n, _, _ in after["estimates"])  # type: ignore[attr-defined]
    same = before["violated"] == after["violated"]
    counts = ", ".join(f"{e[0]} {e[1]}/{e[2]}" for e in after["estimates"])  # type: ignore[attr-defined]
    return (f"after: {counts}; every count after inside the 95 % interval before: {inside}; "
            f"the same properties violated in every simulation: {same}")


def speedup(before_rev: str, rate_n: int, estimate_n: int, workers: int, case: str) -> None:
    """Part 0 (module docstring)."""
    with tempfile.TemporaryDirectory(prefix="twinfleet-before-") as tmp:
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", before_rev],
                                 capture_output=True, check=True).stdout
        subprocess.run(["tar", "-x", "-C", tmp], input=archive, check=True)
        trees = {"before": Path(tmp), "after": ROOT}
        print(f"part 0: {case}, its live.horizon_s of fleet time per simulation, loopback "
              f"model; before = {before_rev}, after = this checkout")
        runs: dict[tuple[str, int], dict[str, object]] = {}
        for label, n, w in (("1 worker", rate_n, 1), (f"{workers} workers", estimate_n, workers)):
            for side, tree in trees.items():
                runs[(side, w)] = _measure(tree, n, w, case)
            wall = {side: n / runs[(side, w)]["wall"] for side in trees}  # type: ignore[operator]
            cpu = {side: n / runs[(side, w)]["cpu"] for side in trees}  # type: ignore[operator]
            print(f"{label:<10} {n:>4} simulations: wall: before {wall['before']:6.2f} sim/s, "
                  f"after {wall['after']:6.2f} sim/s, after / before "
                  f"{wall['after'] / wall['before']:.2f}; per CPU s of all its processes: "
                  f"before {cpu['before']:6.2f}, after {cpu['after']:6.2f}, after / before "
                  f"{cpu['after'] / cpu['before']:.2f} (load average "
                  f"{os.getloadavg()[0]:.1f})", flush=True)
        print(f"estimates of {estimate_n}: " + _agree(runs[("before", workers)],
                                                      runs[("after", workers)]))


def main() -> None:
    """Run the parts and print their tables."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--simulations", type=int, default=8, help="per case in part 1")
    ap.add_argument("--cases", default=",".join(CASES), help="comma-separated case names")
    ap.add_argument("--workers", type=int, default=2, help="workers of part 0's second run and of part 2")
    ap.add_argument("--no-contract-checks", dest="verify", action="store_false",
                    help="skip the node-contract checks of every handler run (both parts)")
    ap.add_argument("--skip-precision", action="store_true", help="skip part 2")
    ap.add_argument("--before", default="3ae704d",
                    help="part 0: the git revision whose engine is 'before' (default 3ae704d)")
    ap.add_argument("--rate-simulations", type=int, default=32,
                    help="part 0: simulations on 1 worker, each side")
    ap.add_argument("--estimate", type=int, default=400,
                    help="part 0: simulations on --workers workers whose estimates are compared")
    ap.add_argument("--speedup-case", default="c1a",
                    help="part 0: the case measured (default c1a; c2a's simulations collide)")
    ap.add_argument("--only-speedup", action="store_true", help="part 0 only")
    args = ap.parse_args()
    speedup(args.before, args.rate_simulations, args.estimate, args.workers, args.speedup_case)
    if args.only_speedup:
        return
    cases = [c for c in args.cases.split(",") if c]
    cases.sort(key=lambda c: c != "c2a")  # c2a first: the reference of "vs c2a"
    print(f"part 1: {args.simulations} simulations per case, 1 worker, contract checks "
          f"{'on' if args.verify else 'off'}, loopback timing model")
    print(f"{'case':<12} {'sim/s':>8} {'steps/s':>9} {'vs c2a':>7}  ended")
    rates = {}
    for case in cases:
        rates[case] = rate, steps, how, _ = throughput(case, args.simulations, args.verify)
        ref = rates.get("c2a", rates[cases[0]])[0]
        print(f"{case:<12} {rate:>8.2f} {steps:>9,.0f} {rate / ref:>7.2f}  {how}", flush=True)
    if "c2a" in rates:
        rate, steps, _, plain = throughput("c2a", args.simulations, args.verify, reuse=False)
        print(f"{'c2a, every handler run':<22} {rate:>8.2f} sim/s {steps:>9,.0f} steps/s; keeping "
              f"handler runs is {rates['c2a'][0] / rate:.2f}x faster; same simulations: "
              f"{_same(plain, rates['c2a'][3])}", flush=True)
    if args.skip_precision:
        return
    print(f"part 2: c2a to a 95 % interval of half-width <= 0.05 on {args.workers} workers")
    start = time.perf_counter()
    result = check_statistical(ROOT / "twinfleet" / "launch" / "c2a.yaml", StatisticalOptions(
        precision=0.05, confidence=0.95, workers=args.workers, verify=args.verify,
        traces_out=str(ROOT / "out" / "bench"), max_traces=0))
    wall = time.perf_counter() - start
    widest = max(result.estimates(), key=lambda e: e.high - e.low)
    print(f"c2a: {len(result.simulations)} simulations, {wall:.1f} s on {args.workers} workers "
          f"({len(result.simulations) / wall:.2f} simulations/s; {result.stopped}); widest "
          f"interval {widest.name} {widest.p:.3f} [{widest.low:.3f}, {widest.high:.3f}]; "
          f"time / 10-minute target = {wall / TARGET_S:.3f}")


if __name__ == "__main__":
    main()
