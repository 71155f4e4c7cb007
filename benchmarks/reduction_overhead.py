"""What the partial-order reduction's bookkeeping costs per transition (docs/reduction.md).

"Reduced transitions/s over unreduced transitions/s" mixes two things: the
reduction's own work per world (the closure, visibility, the cycle proviso,
restarts) and the kind of transition it leaves (nearly every one reaches a new
world and needs a fresh handler run, while 96 % of the unreduced search's
transitions on C1a are cache hits). This script separates them, in one
process, on each scenario (default `launch/c1a.yaml`, BFS to the end):

- `none`: the unreduced search;
- `bookkeeping`: every world's persistent set is computed exactly as `por`
  computes it (variants, closure, visibility, pair checks of declared
  commuting handlers), then the world is expanded fully anyway and its
  transitions checked for falling goal atoms, as `por` checks them: the same transitions as `none`, plus all of the bookkeeping,
  so its transitions/s over `none`'s is the cost;
- `por`: the reduced search.

    python3 benchmarks/reduction_overhead.py [SCENARIO ...] [--repeat 3]

Each round runs every mode once, `--repeat` rounds, and the fastest run of a
mode counts (the machine may be shared); the per-round ratios of `bookkeeping`
to `none` are printed too, with their median. Printed: states, transitions, seconds, transitions/s, and the ratios
against `none`.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from twinfleet.checker.driver import load  # noqa: E402
from twinfleet.checker.properties import PropertySet  # noqa: E402
from twinfleet.checker.reduction import Reduction  # noqa: E402
from twinfleet.checker.search import Search  # noqa: E402
from twinfleet.checker.system import System  # noqa: E402


class BookkeepingOnly(Reduction):
    """Computes every world's persistent set like `por`, then expands the world fully.

    It never restarts: it prunes nothing, so a grown send relation invalidates nothing
    (`por`'s own restarts, in its first few hundred worlds, are in the `por` row).
    """

    def successors(self, world: Any, find: Any, done: int | None) -> list[Any]:
        enabled = self.rules.enabled(world.events)
        self._choose(world, enabled)
        return self._observed(world, list(self.system.successors(world, enabled)))

    @property
    def stale(self) -> bool:
        return False


def run_once(path: str, mode: str) -> tuple[int, int, float]:
    """(states, transitions, seconds) of one BFS of `path` in `mode`."""
    scenario = load(path)
    props = PropertySet.from_scenario(scenario)
    system = System(scenario, properties=props)
    reduction = {"none": None, "bookkeeping": BookkeepingOnly, "por": Reduction}[mode]
    search = Search(system, props, handle_sigint=False,
                    reduction=None if reduction is None else reduction(system, props))
    s = search.run("bfs").statistics
    return s.states, s.transitions, s.elapsed_s


MODES = ("none", "bookkeeping", "por")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenarios", nargs="*", default=[str(ROOT / "twinfleet" / "launch" / "c1a.yaml")])
    parser.add_argument("--repeat", type=int, default=3,
                        help="rounds; each round runs every mode once (fastest counts)")
    args = parser.parse_args(argv)
    print(f"{'scenario':<12}{'mode':<13}{'states':>9}{'transitions':>13}{'s':>7}"
          f"{'tr/s':>9}{'x tr/s':>8}{'x time':>8}")
    for path in args.scenarios:
        # Modes take turns within a round, so a slow spell of a shared machine hits all of
        # them; each round's bookkeeping/none ratio is kept too (its median is printed).
        runs: dict[str, list[tuple[int, int, float]]] = {m: [] for m in MODES}
        for _ in range(args.repeat):
            for mode in MODES:
                runs[mode].append(run_once(path, mode))
        base = None
        for mode in MODES:
            states, transitions, seconds = min(runs[mode], key=lambda r: r[2])
            rate = transitions / max(seconds, 1e-6)
            base = base or (rate, seconds)
            print(f"{Path(path).stem:<12}{mode:<13}{states:>9,}{transitions:>13,}{seconds:>7.2f}"
                  f"{rate:>9,.0f}{rate / base[0]:>8.2f}{base[1] / seconds:>8.2f}")
        ratios = sorted(n[2] / b[2] for n, b in zip(runs["none"], runs["bookkeeping"],
                                                     strict=True))
        print(f"{Path(path).stem:<12}bookkeeping/none per round: "
              f"{', '.join(f'{r:.2f}' for r in ratios)} (median {ratios[len(ratios) // 2]:.2f})")
    print("x tr/s: transitions/s over `none`'s (bookkeeping: the reduction's cost per "
          "transition; target >= 0.8); x time: `none`'s seconds over this mode's.")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
