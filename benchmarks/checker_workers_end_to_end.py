"""`twinfleet check --workers N` against one process, end to end: the command's wall time.

benchmarks/checker_distributed.py times the search itself on a cluster started
beforehand; a user waits for the whole command, the local cluster's start and stop
included. Here each round runs, one right after the other (their order alternating
from round to round: this machine's speed drifts), the command in one process and
with `--workers N` as subprocesses, and prints for each run its wall time, its
transitions per second of wall time, the peak memory of all its processes together
(the command and every process it started: Ray's GCS, raylet and workers, sampled
every 0.1 s), the CPU time of the command's own process and its share of the wall
time (what the search got of its core: a cluster starting beside it takes from that
share, as does the rest of a busy machine) and where the search ran (the summary's engine line); then per case the
ratio of the rates of each round's pair, their median and range. A search cut by
`--max-time` compares rates; a complete one, wall times (the same ratio).

Cases (safety properties only, as in checker_distributed.py):
- `lanes4_jitter`: four robots in lanes, every delivery 0-1 ms late, unreduced
  (about 700,000 states, 25-40 s in one process here);
- `lanes3_jitter`: three robots, the same (431,142 transitions: a search of 6-7 s
  here now); `lanes3_jitter_52`: the same robots in lanes of 52 columns instead of 36
  (about 660,000 transitions: the 10-s search of the aim); any `lanesN_jitter_L` works;
- `c1a_jitter`: the paper's C1a with deliveries 0-1 ms late, unreduced (levels of
  tens of thousands of worlds; cut by --max-time);
- `c1a_none`: C1a unreduced (41,608 states; below the size at which a cluster starts).

    python benchmarks/checker_workers_end_to_end.py [--cases lanes4_jitter,lanes3_jitter]
        [--workers 2] [--repeat 3] [--max-time 120]

The acceptance run (the wide case and the 10-s case, three rounds each, about 8 minutes
on an idle 2-core machine):

    python benchmarks/checker_workers_end_to_end.py --cases lanes4_jitter,lanes3_jitter_52 \
        --repeat 3 --max-time 50
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "benchmarks")]

from checker_distributed import safety_only  # noqa: E402
from checker_scaling import LANE_LENGTH, lanes_scenario  # noqa: E402

from twinfleet.cli import main as cli  # noqa: E402

CASES = ("lanes4_jitter", "lanes3_jitter", "c1a_jitter", "c1a_none")
JITTER = {"latency": {"default": [0, 1]}}
CLOCK_TICKS = os.sysconf("SC_CLK_TCK")


def scenario(case: str, out: Path) -> Path:
    """The scenario file of `case`, written into `out`."""
    if case.startswith("lanes"):
        robots, _, length = case.removeprefix("lanes").partition("_jitter")
        return safety_only(lanes_scenario(out, int(robots), "ros",
                                          int(length[1:]) if length else LANE_LENGTH), **JITTER)
    if case in ("c1a_jitter", "c1a_none"):
        cli(["examples", "--copy", "c1a", str(out)])
        return safety_only(out / "c1a.yaml", **(JITTER if case == "c1a_jitter" else {}))
    raise SystemExit(f"unknown case {case!r} (known: {', '.join(CASES)})")


@dataclass(frozen=True)
class Run:
    """One command's measures."""

    wall_s: float
    transitions: int
    peak_mb: float
    cpu_s: float
    engine: str

    @property
    def rate(self) -> float:
        """Transitions per second of the command's wall time."""
        return self.transitions / self.wall_s


def _tree_rss_kb(root: int) -> int:
    """The resident memory of `root` and all its descendants, in kB (from /proc)."""
    parents: dict[int, int] = {}
    rss: dict[int, int] = {}
    for entry in Path("/proc").glob("[0-9]*"):
        try:
            status = (entry / "status").read_text()
        except OSError:
            continue
        fields = dict(line.split(":", 1) for line in status.splitlines() if ":" in line)
        parents[int(entry.name)] = int(fields.get("PPid", "0"))
        rss[int(entry.name)] = int(fields.get("VmRSS", "0 kB").split()[0])
    tree, frontier = {root}, {root}
    while frontier:
        frontier = {pid for pid, parent in parents.items() if parent in frontier} - tree
        tree |= frontier
    return sum(rss.get(pid, 0) for pid in tree)


def _cpu_s(pid: int) -> float:
    """The user and system CPU time of process `pid` so far (0 once it ended)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return 0.0
    fields = stat[stat.rindex(")") + 2:].split()
    return (int(fields[11]) + int(fields[12])) / CLOCK_TICKS


def command(path: Path, reduction: str, max_time: float, workers: int) -> Run:
    """Run `twinfleet check` on `path` as a subprocess and measure it."""
    argv = [sys.executable, "-m", "twinfleet", "check", str(path), "--reduction", reduction,
            "--max-time", str(max_time), *(["--workers", str(workers)] if workers > 1 else [])]
    start = time.perf_counter()
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                            cwd=path.parent)
    peak = [0]
    cpu = [0.0]  # the command's own CPU time, as last sampled (within 0.1 s of its end)

    def sample() -> None:
        while proc.poll() is None:
            peak[0] = max(peak[0], _tree_rss_kb(proc.pid))
            cpu[0] = max(cpu[0], _cpu_s(proc.pid))
            time.sleep(0.1)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    out, _ = proc.communicate()
    wall = time.perf_counter() - start
    sampler.join()
    found = re.search(r"transitions ([\d,]+)", out)
    if found is None:  # exit 2 is also a search cut by --max-time: it has its counts
        raise SystemExit(f"{' '.join(argv)}: exit {proc.returncode}")
    engine = next((line[len("engine: "):] for line in out.splitlines()
                   if line.startswith("engine: ")), "one process")
    return Run(wall, int(found.group(1).replace(",", "")), peak[0] / 1024, cpu[0], engine)


def _line(label: str, run: Run) -> str:
    return (f"  {label:<14} {run.wall_s:6.1f} s  {run.transitions:>10,} transitions  "
            f"{run.rate:>8,.0f} tr/s  peak {run.peak_mb:6.0f} MB  "
            f"cpu {run.cpu_s:5.1f} s ({run.cpu_s / run.wall_s:.2f} of wall)  {run.engine[:90]}")


def case_rounds(path: Path, reduction: str, max_time: float, workers: int,
                repeat: int) -> list[float]:
    """`repeat` rounds of the pair, printed as they end; the rounds' ratios."""
    ratios = []
    for r in range(repeat):
        order = (1, workers) if r % 2 == 0 else (workers, 1)
        runs = {n: command(path, reduction, max_time, n) for n in order}
        for n in order:
            print(_line("one process" if n == 1 else f"{n} workers", runs[n]), flush=True)
        ratios.append(runs[workers].rate / runs[1].rate)
        print(f"  round {r + 1}: x{ratios[-1]:.2f}", flush=True)
    return ratios


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--cases", default="lanes4_jitter,lanes3_jitter",
                   help=f"comma-separated cases among {', '.join(CASES)}")
    p.add_argument("--workers", type=int, default=2, help="workers of the distributed runs")
    p.add_argument("--repeat", type=int, default=3, help="rounds of each pair")
    p.add_argument("--max-time", type=float, default=120.0,
                   help="--max-time of every command (seconds)")
    args = p.parse_args()
    summary = []
    with tempfile.TemporaryDirectory() as tmp:
        for case in args.cases.split(","):
            out = Path(tmp) / case
            out.mkdir()
            path = scenario(case, out)
            print(f"{case} (reduction none, --max-time {args.max_time:g}):", flush=True)
            ratios = case_rounds(path, "none", args.max_time, args.workers, args.repeat)
            summary.append(f"  {case:<16} x{statistics.median(ratios):.2f} median "
                           f"(x{min(ratios):.2f}-x{max(ratios):.2f} over {len(ratios)} rounds)")
    print(f"--workers {args.workers} against one process, end to end:")
    print("\n".join(summary))


if __name__ == "__main__":
    main()
