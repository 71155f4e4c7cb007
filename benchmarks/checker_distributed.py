"""The exhaustive search on Ray workers against one process, on wide searches.

For each case, measured in this run: the single-process search (`twinfleet check`) and
the distributed one on 1 and 2 Ray workers of a local cluster (one started before each
distributed search: its start-up is not in the figures, its workers' is), from the first
level (--min-width 1, the engine itself) and, on 2 workers, with the default --min-width
(what `check --workers 2` does: narrow levels stay in one process), each for `--max-time` seconds or to the end. Printed per case: states, transitions, transitions/s, the ratio to the single
process, handler runs (outcome-cache misses, all processes) per transition against the
single process's, levels, and for a reduced search that started again after learning a
send, the rate of its last attempt (what it counts: the transitions since that restart)
and that rate's ratio, which leaves out the restarts' narrow early levels and the walk
ahead that both engines spend, the workers at a few round trips a level; claims per state (16-byte messages to the shard owning a
digest) and worlds moved between workers per state (work sharing). With `--two-nodes`:
the same on a simulated two-node cluster (`ray.cluster_utils.Cluster`, one CPU per node).
With `--sweep`: a 24-point `twinfleet sweep` of C2a (r4's speed x the scan period), its
points one after another against 2 local workers, wall time of each.

Cases (every eventually property dropped: those keep a search in one process):
- `c1a_jitter`: the paper's C1a (fixed profile, ros) with `check: {latency: {default:
  [0, 1]}}`, unreduced: levels of tens of thousands of worlds;
- `c1a_jitter_por`: the same with the partial-order reduction (the issue's 5,994,253
  states in 582 s on one core);
- `lanes6`: six robots in separate lanes (benchmarks/checker_scaling.py), unreduced;
- `crossing6`: six robots crossing on maps/random100, unreduced.

    python benchmarks/checker_distributed.py [--cases c1a_jitter,lanes6] [--max-time 60]
        [--repeat 3] [--two-nodes] [--sweep]

This machine has 2 cores that Ray's own processes and the coordinator share with the
workers: read the ratios, and run it on an otherwise idle machine.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "benchmarks")]

from checker_scaling import crossing_scenario, lanes_scenario  # noqa: E402

from twinfleet.checker import CheckOptions, CheckResult, check  # noqa: E402
from twinfleet.checker.cluster import engine_module  # noqa: E402
from twinfleet.checker.options import MIN_WIDTH  # noqa: E402
from twinfleet.cli import main as cli  # noqa: E402

CASES = ("c1a_jitter", "c1a_jitter_por", "lanes6", "crossing6")
REDUCED = frozenset({"c1a_jitter_por"})
SWEEP = ("c2a", "*.allow_unsafe_speed:=true", "--param", "r4.speed=0.3:1.0:0.1",
         "--param", "scan_rate_ms=60:140:40", "--max-time", "120")  # 8 x 3 points


def safety_only(path: Path, **check_block: Any) -> Path:
    """Rewrite a scenario without eventually properties (and with `check:` additions)."""
    doc = yaml.safe_load(path.read_text())
    doc["properties"] = [p for p in doc["properties"] if p["kind"] != "eventually"]
    if check_block:
        doc.setdefault("check", {}).update(check_block)
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def scenario(case: str, out: Path) -> Path:
    """The scenario file of `case`, written into `out`."""
    if case in ("c1a_jitter", "c1a_jitter_por"):
        cli(["examples", "--copy", "c1a", str(out)])
        return safety_only(out / "c1a.yaml", latency={"default": [0, 1]})
    if case == "lanes6":
        return safety_only(lanes_scenario(out, 6, "ros"))
    if case == "crossing6":
        return safety_only(crossing_scenario(out, 6, 3, "ros"))
    raise SystemExit(f"unknown case {case!r} (known: {', '.join(CASES)})")


def cases(names: str, tmp: Path) -> Iterator[tuple[str, Path, str]]:
    """(case, its scenario file written under `tmp`, its reduction) of each of the
    comma-separated `names`."""
    for case in names.split(","):
        out = tmp / case
        out.mkdir()
        yield case, scenario(case, out), "por" if case in REDUCED else "none"


def _rate(result: CheckResult) -> float:
    return result.statistics.transitions_per_s


def _number(pattern: str, text: str) -> float | None:
    found = re.search(pattern, text)
    return None if found is None else float(found.group(1).replace(",", ""))


def _runs_per_transition(result: CheckResult) -> float:
    runs = _number(r"([\d,]+) handler runs", result.engine or "")
    total = result.handler_runs if runs is None else runs
    return total / max(1, result.statistics.transitions)


def _traffic(result: CheckResult) -> str:
    """Claims and moved worlds per state, read from the summary's engine line."""
    note = result.engine or ""
    claims = _number(r"([\d.]+) claims per state", note)
    moved = _number(r"([\d,]+) worlds moved", note)
    levels = _number(r"\((\d+) levels", note)
    if claims is None or moved is None:
        return f"(stayed in one process: {note})"
    per_moved = moved / max(1, result.statistics.states)
    order = "relaxed order" if levels is None else f"levels {levels:.0f}"
    return f"{order}, claims/state {claims:.2f}, moved/state {per_moved:.3f}"


def row(label: str, runs: list[CheckResult], base: list[CheckResult] | None) -> str:
    """One configuration's line: its median run (by transitions/s), with the range of
    the rates when it ran more than once, and ratios of medians to the single process."""
    result = median(runs)
    s = result.statistics
    per = _runs_per_transition(result)
    spread = "" if len(runs) < 2 else \
        f" ({min(map(_rate, runs)):,.0f}-{max(map(_rate, runs)):,.0f})"
    ratio = ""
    if base is not None:
        one = median(base)
        ratio = (f"  x{_rate(result) / _rate(one):.2f}  handler runs x"
                 f"{per / max(_runs_per_transition(one), 1e-12):.2f}")
        if s.attempt_s is not None:
            base_rate = max(one.statistics.attempt_transitions_per_s, 1e-9)
            ratio += f"  last attempt x{s.attempt_transitions_per_s / base_rate:.2f}"
    extra = "" if result.engine is None else f"  {_traffic(result)}"
    attempt = "" if s.attempt_s is None else \
        f" [last attempt {s.attempt_transitions_per_s:,.0f} tr/s in {s.attempt_s:.0f} s]"
    return (f"  {label:<22} {result.status.value:<8} states {s.states:>10,}  transitions "
            f"{s.transitions:>11,}  {_rate(result):>9,.0f} tr/s{spread}{attempt}  runs/tr "
            f"{per:.3f}{ratio}{extra}")


def median(runs: list[CheckResult]) -> CheckResult:
    """The run with the median transitions/s (the lower middle one of an even count)."""
    return sorted(runs, key=_rate)[(len(runs) - 1) // 2]


def measure(path: Path, max_time: float, session: Callable[[], AbstractContextManager[Any]],
            workers: tuple[int, ...], label: str, reduction: str, *,
            default_width: bool = False, repeat: int = 1) -> None:
    """One process, then `workers` on the cluster `session` makes from the first level
    (--min-width 1: the engine itself), printed as rows; with `default_width` also 2
    workers with the default --min-width (what `check --workers 2` does). `repeat`
    rounds of all of them, one after another, and each row is the median of its rounds:
    this machine's speed drifts by 10-20 % from minute to minute. Every distributed search
    gets a cluster started afresh (the single process runs while none is up), as `check
    --workers N` starts its own: its workers then take the processes Ray starts with the
    cluster. The row "again" is a second search on the cluster of the last `workers`
    row, as with `--cluster`: its workers wait for new processes (0.3-0.5 s more here,
    which a 4-s search feels)."""
    runs: dict[str, list[CheckResult]] = {}

    def timed(name: str, **options: Any) -> None:
        runs.setdefault(name, []).append(
            check(path, CheckOptions(reduction=reduction, max_time_s=max_time, **options)))

    for _ in range(repeat):
        timed("one process")
        for n in workers:
            with session() as address:
                timed(f"{label}, {n} worker(s)", workers=n, cluster=address, min_width=1)
                if n == workers[-1]:
                    timed(f"{label}, {n}, again", workers=n, cluster=address, min_width=1)
        if default_width:
            with session() as address:
                timed(f"{label}, 2, width {MIN_WIDTH}", workers=2, cluster=address)
    base = runs.pop("one process")
    print(row("one process", base, None), flush=True)
    for name, found in runs.items():
        print(row(name, found, base), flush=True)


def sweep(out: Path) -> None:
    """The 24-point sweep, serial then on 2 local workers (each with its own cache)."""
    times = []
    for workers in (1, 2):
        start = time.perf_counter()
        done = subprocess.run([sys.executable, "-m", "twinfleet", "sweep", *SWEEP, "--workers",
                               str(workers), "--out", str(out / f"sweep{workers}")],
                              capture_output=True, text=True, cwd=out, check=False)
        times.append(time.perf_counter() - start)
        if done.returncode not in (0, 1):
            raise SystemExit(f"sweep failed: {done.stderr.strip().splitlines()[-1:]}")
        print(f"  sweep, 24 points, {workers} worker(s): {times[-1]:.1f} s", flush=True)
    print(f"  sweep speed-up on 2 workers: x{times[0] / times[1]:.2f}", flush=True)


class _TwoNodes(AbstractContextManager[str]):
    """A simulated two-node Ray cluster (one CPU per node), joined by this process."""

    def __enter__(self) -> str:
        import ray
        from ray.cluster_utils import Cluster

        self.cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1})
        self.cluster.add_node(num_cpus=1)
        ray.init(address=self.cluster.address, log_to_driver=False, configure_logging=False,
                 runtime_env={"env_vars": {"PYTHONPATH": str(ROOT)}})
        return str(self.cluster.address)

    def __exit__(self, *exc: object) -> None:
        import ray

        ray.shutdown()
        self.cluster.shutdown()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--cases", default=",".join(CASES), help="comma-separated cases")
    p.add_argument("--max-time", type=float, default=60.0, help="seconds per search")
    p.add_argument("--repeat", type=int, default=1,
                   help="rounds of every search; rows show the median (and the range)")
    p.add_argument("--two-nodes", action="store_true",
                   help="also run 2 workers on a simulated two-node cluster")
    p.add_argument("--sweep", action="store_true",
                   help="also time a 24-point sweep, serial against 2 workers")
    args = p.parse_args()
    engine = engine_module()  # before Ray is imported: a loopback cluster

    def local() -> AbstractContextManager[Any]:
        return _Local(engine)

    with tempfile.TemporaryDirectory() as tmp:
        for case, path, reduction in cases(args.cases, Path(tmp)):
            print(f"{case} (reduction {reduction}, up to {args.max_time:g} s per search):",
                  flush=True)
            measure(path, args.max_time, local, (1, 2), "local Ray", reduction,
                    default_width=True, repeat=args.repeat)
            if args.two_nodes:
                measure(path, args.max_time, _TwoNodes, (2,), "two nodes", reduction,
                        repeat=args.repeat)
        if args.sweep:
            print("sweep (C2a, r4.speed 0.3-1.0 x scan_rate_ms 60-140):", flush=True)
            sweep(Path(tmp))


class _Local(AbstractContextManager[str]):
    """A local Ray cluster of 2 workers on loopback, started before the timed searches."""

    def __init__(self, engine: Any) -> None:
        self.session = engine.session(2, None)

    def __enter__(self) -> str:
        self.session.__enter__()
        return "this process's"

    def __exit__(self, *exc: object) -> None:
        self.session.__exit__(None, None, None)


if __name__ == "__main__":
    main()
