"""What the user waits for: `twinfleet check c1a_rebeca` end to end, as a command.

    python3 benchmarks/c1a_rebeca_wall.py [--baseline PATH] [--runs N] [--scenario NAME]

Runs `python -m twinfleet check SCENARIO --quiet` as a subprocess `runs` times
(interpreter start, imports, scenario load, the search and the summary) and
prints, per run and as min / median, the wall time and the CPU time the command
used (user + system, from the child's own resource usage: less affected than
wall time by the other jobs of a shared machine). With `--baseline PATH` (a
checkout of another version, e.g. `git worktree add /tmp/base main`) the
baseline runs in the same session, alternating with this checkout, and the
ratios baseline / this checkout come last. Every run's counts must be RMC's
(c1a_rebeca: 18,527 states / 43,076 transitions) on both sides, or it stops.
The load averages before and after are printed: wall times mean little above
a load of 1 on this 2-core machine. Compare sides that both have their bytecode
cached (or neither): with PYTHONDONTWRITEBYTECODE set and no __pycache__, every
run compiles the modules it imports again (the script says which side has it).
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]
_COUNTS = re.compile(r"states ([\d,]+)\s+transitions ([\d,]+)")


@dataclass(frozen=True)
class Run:
    """One command's wall and CPU seconds and the counts it printed."""

    wall_s: float
    cpu_s: float
    counts: tuple[int, int]


def run_once(checkout: Path, scenario: str) -> Run:
    """`python -m twinfleet check SCENARIO --quiet` with `checkout` first on the path."""
    env = {**os.environ, "PYTHONPATH": str(checkout)}
    with tempfile.TemporaryFile("w+") as out:
        started = time.perf_counter()
        child = subprocess.Popen([sys.executable, "-m", "twinfleet", "check", scenario,
                                  "--quiet"], cwd=checkout, env=env, stdout=out,
                                 stderr=subprocess.STDOUT)
        _, status, usage = os.wait4(child.pid, 0)  # the child's own CPU time
        wall = time.perf_counter() - started
        child.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        text = out.read()
    found = _COUNTS.search(text)
    if child.returncode != 0 or found is None:
        sys.exit(f"c1a_rebeca_wall: {checkout}: exit {child.returncode}:\n{text}")
    return Run(wall, usage.ru_utime + usage.ru_stime,
               (int(found[1].replace(",", "")), int(found[2].replace(",", ""))))


def _summary(label: str, runs: list[Run]) -> tuple[float, float]:
    walls, cpus = [r.wall_s for r in runs], [r.cpu_s for r in runs]
    print(f"{label:>9}: wall min {min(walls):.2f} s  median {statistics.median(walls):.2f} s   "
          f"CPU min {min(cpus):.2f} s  median {statistics.median(cpus):.2f} s   "
          f"({len(runs)} runs)")
    return statistics.median(walls), statistics.median(cpus)


def main() -> int:
    """Parse the arguments, time the command, print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--baseline", type=Path, metavar="PATH",
                        help="a checkout of another version, run alternately in the same session")
    parser.add_argument("--runs", type=int, default=5, help="runs per side (default 5)")
    parser.add_argument("--scenario", default="c1a_rebeca",
                        help="a shipped scenario's name or a file (default c1a_rebeca)")
    args = parser.parse_args()
    sides = {"this": HERE, **({"baseline": args.baseline.resolve()} if args.baseline else {})}
    for label, path in sides.items():
        if not (path / "twinfleet" / "__init__.py").is_file():
            sys.exit(f"c1a_rebeca_wall: --baseline {path}: no twinfleet/__init__.py there")
        cached = (path / "twinfleet" / "__pycache__").is_dir()
        print(f"{label}: {path} (bytecode {'cached' if cached else 'not cached: compiled every run'})")
    print(f"load before: {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f}; "
          f"PYTHONDONTWRITEBYTECODE={os.environ.get('PYTHONDONTWRITEBYTECODE', '')!r}")
    results: dict[str, list[Run]] = {label: [] for label in sides}
    for i in range(args.runs):
        for label, path in sides.items():
            run = run_once(path, args.scenario)
            results[label].append(run)
            print(f"run {i + 1} {label:>8}: wall {run.wall_s:.2f} s  CPU {run.cpu_s:.2f} s  "
                  f"states {run.counts[0]:,} transitions {run.counts[1]:,}", flush=True)
    counts = {r.counts for runs in results.values() for r in runs}
    if len(counts) != 1:
        sys.exit(f"c1a_rebeca_wall: the counts differ between runs: {sorted(counts)}")
    print(f"load after: {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f}")
    medians = {label: _summary(label, runs) for label, runs in results.items()}
    if "baseline" in medians:
        (bw, bc), (tw, tc) = medians["baseline"], medians["this"]
        print(f"baseline / this (medians): wall x{bw / tw:.2f}  CPU x{bc / tc:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
