"""Does the partial-order reduction pay for itself? `por` against `none`, side by side.

Every scenario the script can find is checked both ways in one process, the modes
taking turns within each round so that a slow spell of the shared machine hits both.
`por` is what `check` runs by default, late start included (`checker.late_start`: a
search of under 1,000 worlds runs unreduced, a larger one starts again reduced or steps
aside); `--eager` reduces from the first world instead, to see what the late start saves.
The scenarios:

- the shipped examples (`twinfleet/launch/*.yaml`; `demo` never ends, and under `rebeca`
  the reduction is off by plan, which the row says instead of timing identical work);
- the scenarios under `tests/data` (the station, the two-phase commit with 0-2 ms of
  latency: a protocol where `por` has little to prune) and the rclpy programs of
  `tests/rclpy/programs` (each a few dozen worlds);
- the generated systems of the differential tests (`tests/checker/program_systems.py`,
  derandomized: the same systems each run), plain and crowded, as two rows whose time
  is the sum over their systems (each takes milliseconds alone); a system that reaches
  the tests' 3,000-world limit is left out, as there.

Time is the CPU time (`time.process_time`) of the `check` call, System build included,
the fastest of `--repeat` rounds per mode: on a machine shared by several jobs, CPU time
does not count the waits for a core. A row whose unreduced checks take under 0.3 s is
checked that many times more within each round (after a first, untimed round: a
process's first check also imports), the modes taking turns check by check, and its
time is per check. Printed per row: states and seconds of each mode,
their ratio (`por` seconds over `none` seconds: above 1 the reduction cost time), the
spread of the per-round ratios, and what the reduction did; the worst ratio last, over
the rows whose unreduced check takes 0.5 s or more and over all (a check of a few
milliseconds is mostly its fixed costs).

    python3 benchmarks/reduction_overhead.py [SCENARIO ...] [--repeat 3] [--generated 100]
                                             [--eager]

`--bookkeeping SCENARIO` instead measures what the reduction's work per world costs:
every world's persistent set is computed as `por` computes it, then the world is
expanded fully anyway (the transitions of `none` plus all of the bookkeeping).
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from twinfleet.checker.driver import CheckOptions, check, load  # noqa: E402
from twinfleet.checker.options import REDUCE_FROM  # noqa: E402
from twinfleet.checker.properties import PropertySet  # noqa: E402
from twinfleet.checker.reduction import Reduction, plan  # noqa: E402
from twinfleet.checker.search import Search  # noqa: E402
from twinfleet.checker.system import System  # noqa: E402

LAUNCH = ROOT / "twinfleet" / "launch"
DATA = ROOT / "tests" / "data"
RCLPY = ROOT / "tests" / "rclpy" / "programs"  # unmodified rclpy nodes (`twinfleet.rclpy`)
NEVER_ENDS = {"demo"}  # its talker counts for ever
GENERATED_LIMIT = 3_000  # the differential tests' state limit
LONG_S = 0.5  # rows at least this long (unreduced CPU seconds) get a worst ratio of their own
TINY_S = 0.3  # a row's checks are repeated within a round until the unreduced ones take this
TIMES_MAX = 200  # most checks of one row per mode and round


@dataclass
class Run:
    """One mode's fastest run of a row and its per-round times."""

    states: int = 0
    seconds: float = float("inf")
    rounds: list[float] | None = None
    reduction: str = ""
    aside: int = 0  # systems of a generated row where the reduction stepped aside


def check_time(path: Path, mode: str, max_states: int | None = None,
               reduce_from: int = REDUCE_FROM) -> tuple[int, float, str]:
    """(states, CPU seconds, the summary's reduction line) of one check of `path`; states
    -1 when it reached `max_states`."""
    started = time.process_time()
    result = check(path, CheckOptions(reduction=mode, max_states=max_states,
                                      reduce_from=reduce_from))
    seconds = time.process_time() - started
    hit = max_states is not None and result.statistics.states >= max_states
    return (-1 if hit else result.statistics.states), seconds, result.reduction


def reduction_off(path: Path) -> str | None:
    """Why `por` would not run on `path` at all (decided before any search), or None."""
    scenario = load(str(path))
    props = PropertySet.from_scenario(scenario)
    reduction, name = plan(System(scenario, properties=props), props, "bfs", "por")
    return None if reduction is not None else name


def turns(path: Path, times: int, max_states: int | None, reduce_from: int
          ) -> dict[str, tuple[int, float, str]]:
    """Check `path` `times` times in each mode, the modes taking turns; per mode the states,
    the CPU seconds per check and the reduction line."""
    done: dict[str, tuple[int, float, str]] = {}
    for _ in range(times):
        for mode in ("none", "por"):
            states, seconds, line = check_time(path, mode, max_states, reduce_from)
            done[mode] = (states, done.get(mode, (0, 0.0, ""))[1] + seconds / times, line)
    return done


def rounds(paths: Sequence[Path], repeat: int, max_states: int | None = None,
           reduce_from: int = REDUCE_FROM) -> dict[str, Run] | None:
    """Check every path of a row in both modes, `repeat` rounds; None if a path of a single
    row hits the limit. Several paths (generated systems) add up, leaving out those at the
    limit. A row whose unreduced checks take under `TINY_S` in all is checked again within
    each round until they take that long (the number of checks fixed by a first, untimed
    round), and its time is per check: one check of a few milliseconds is mostly noise."""
    runs = {mode: Run(rounds=[]) for mode in ("none", "por")}
    kept = list(paths)
    times, first = 1, True
    while len(runs["none"].rounds or ()) < repeat:
        totals = {"none": 0.0, "por": 0.0}
        for path in list(kept):
            done = turns(path, times, max_states, reduce_from)
            if any(states < 0 for states, _, _ in done.values()):
                kept.remove(path)
                continue
            for mode, (states, seconds, line) in done.items():
                totals[mode] += seconds
                run = runs[mode]
                if first:
                    run.states += states
                    run.aside += "stepped aside" in line
                run.reduction = line if len(paths) == 1 else f"{run.aside} stepped aside"
        if not kept:
            return None
        if first:
            first = False
            times = min(TIMES_MAX, math.ceil(TINY_S / max(totals["none"], 1e-4)))
            if times > 1:
                continue
        for mode, total in totals.items():
            runs[mode].seconds = min(runs[mode].seconds, total)
            assert runs[mode].rounds is not None
            runs[mode].rounds.append(total)
    return runs


def row(name: str, runs: dict[str, Run]) -> tuple[float, float]:
    """Print one row; return its ratio and the unreduced check's seconds."""
    none, por = runs["none"], runs["por"]
    ratio = por.seconds / max(none.seconds, 1e-9)
    per_round = sorted(p / max(n, 1e-9) for p, n in zip(por.rounds or (), none.rounds or (),
                                                        strict=True))
    spread = f"{per_round[0]:.2f}-{per_round[-1]:.2f}"
    did = por.reduction if len(por.reduction) < 70 else por.reduction[:67] + "..."
    print(f"{name:<22}{none.states:>9,}{none.seconds:>8.3f}{por.states:>9,}{por.seconds:>8.3f}"
          f"{ratio:>7.2f}  {spread:<11}{did}", flush=True)
    return ratio, none.seconds


def generated(count: int, crowded: bool, folder: Path) -> list[Path]:
    """`count` systems of the differential tests' strategy, derandomized, written out."""
    from hypothesis import HealthCheck, given, settings

    from tests.checker.program_systems import systems, write_scenario

    docs: list[dict[str, Any]] = []

    @settings(max_examples=count, derandomize=True, database=None, deadline=None,
              suppress_health_check=list(HealthCheck))
    @given(doc=systems(crowded=crowded))
    def draw(doc: dict[str, Any]) -> None:
        docs.append(doc)

    draw()
    kind = "crowded" if crowded else "plain"
    return [write_scenario(doc, folder / f"{kind}{i}.yaml") for i, doc in enumerate(docs)]


def shipped() -> Iterable[Path]:
    """The scenarios of the package, of the tests' data and of the rclpy programs' tests."""
    yield from sorted(p for p in LAUNCH.glob("*.yaml") if p.stem not in NEVER_ENDS)
    yield from sorted(p for p in DATA.glob("*/*.yaml"))
    yield from sorted(RCLPY.glob("*.yaml"))


def compare(args: argparse.Namespace) -> int:
    print(f"{'scenario':<22}{'none st.':>9}{'none s':>8}{'por st.':>9}{'por s':>8}{'ratio':>7}"
          f"  {'rounds':<11}reduction")
    found: list[tuple[float, float, str]] = []  # (ratio, none seconds, row)
    for path in args.scenarios or list(shipped()):
        off = reduction_off(path)
        if off is not None:
            print(f"{path.stem:<22}{'':>42}  {'':<11}{off}: the same search either way")
            continue
        runs = rounds([path], args.repeat, reduce_from=0 if args.eager else REDUCE_FROM)
        assert runs is not None
        found.append((*row(path.stem, runs), path.stem))
    if args.generated and not args.scenarios:
        with tempfile.TemporaryDirectory() as tmp:
            for crowded in (False, True):
                count = args.generated if not crowded else max(1, args.generated // 3)
                paths = generated(count, crowded, Path(tmp))
                runs = rounds(paths, args.repeat, GENERATED_LIMIT,
                              0 if args.eager else REDUCE_FROM)
                if runs is not None:
                    name = f"generated {'crowded' if crowded else 'plain'} ({count})"
                    found.append((*row(name, runs), name))
    long = [f for f in found if f[1] >= LONG_S]
    for label, rows in ((f"rows whose unreduced check takes >= {LONG_S:g} s", long),
                        ("all rows", found)):
        if rows:
            ratio, _, name = max(rows)
            print(f"worst ratio (por seconds / none seconds), {label}: {ratio:.2f} ({name}); "
                  "target <= 1.10")
    return 0


class BookkeepingOnly(Reduction):
    """Computes every world's persistent set like `por`, then expands the world fully.

    It never restarts and never steps aside: it prunes nothing, so a grown send relation
    invalidates nothing.
    """

    def successors(self, world: Any, find: Any, done: int | None) -> list[Any]:
        enabled = self.rules.enabled(world.events)
        self._choose(world, enabled)
        return self._observed(world, list(self.system.successors(world, enabled)))

    @property
    def stale(self) -> bool:
        return False

    def steps_aside(self) -> bool:
        return False


def bookkeeping(path: Path, repeat: int) -> int:
    """Print `none`, `bookkeeping` and `por` transitions/s on one scenario."""
    modes: dict[str, Callable[[System, PropertySet], Reduction] | None] = {
        "none": None, "bookkeeping": BookkeepingOnly, "por": Reduction}
    best: dict[str, tuple[int, int, float]] = {}
    for _ in range(repeat):
        for mode, make in modes.items():
            scenario = load(str(path))
            props = PropertySet.from_scenario(scenario)
            system = System(scenario, properties=props)
            started = time.process_time()
            s = Search(system, props, handle_sigint=False,
                       reduction=None if make is None else make(system, props)).run("bfs")
            seconds = time.process_time() - started
            if mode not in best or seconds < best[mode][2]:
                best[mode] = (s.statistics.states, s.statistics.transitions, seconds)
    print(f"{'mode':<13}{'states':>9}{'transitions':>13}{'s':>7}{'tr/s':>9}{'x tr/s':>8}")
    base = best["none"][1] / best["none"][2]
    for mode, (states, transitions, seconds) in best.items():
        rate = transitions / max(seconds, 1e-9)
        print(f"{mode:<13}{states:>9,}{transitions:>13,}{seconds:>7.2f}{rate:>9,.0f}"
              f"{rate / base:>8.2f}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenarios", nargs="*", type=Path,
                        help="scenario files (default: every one found, and generated ones)")
    parser.add_argument("--repeat", type=int, default=3,
                        help="rounds; each runs every mode once, the fastest counts")
    parser.add_argument("--generated", type=int, default=100,
                        help="generated plain systems (a third as many crowded ones); 0: none")
    parser.add_argument("--bookkeeping", type=Path, metavar="SCENARIO",
                        help="measure the reduction's work per world on SCENARIO instead")
    parser.add_argument("--eager", action="store_true",
                        help="por from the first world (no late start), as before it")
    args = parser.parse_args(argv)
    if args.bookkeeping is not None:
        return bookkeeping(args.bookkeeping, args.repeat)
    return compare(args)


if __name__ == "__main__":
    raise SystemExit(main())
