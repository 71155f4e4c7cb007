"""The checker's named choices, light enough for argument parsers: message semantics,
search orders, reductions; the options every command that runs checks declares
(`add_check_arguments`, read back by `SearchChoices.of`), and the options of
statistical checking (`add_statistical_arguments`).

Importing this module loads nothing else of the checker, so `twinfleet --help` and the
commands' parsers can offer the choices without loading the search.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import StrEnum, unique
from typing import Any, Final, final

from twinfleet.runtime.scenario.config import Fairness


@unique
class Semantics(StrEnum):
    """The checker's message semantics, named in a scenario's `semantics:` key.

    It says how messages are delivered, never what the nodes do: `Semantics.REBECA` is
    RMC's message rules, whatever behaviour the nodes' own parameters choose.
    """

    ROS = "ros"  # per-sender FIFO, as Zenoh delivers
    REBECA = "rebeca"  # the Timed Rebeca model checker's rules (Rules 3 and 4)


@unique
class SearchOrder(StrEnum):
    """The order an exhaustive check explores worlds in (`--search`, `check.search`)."""

    BFS = "bfs"  # breadth first: a shortest counterexample
    DFS = "dfs"  # depth first
    RANDOM = "random"  # random walks (finding nothing proves nothing)


@unique
class ReductionMode(StrEnum):
    """Whether a search reduces the interleavings it explores (`--reduction`)."""

    POR = "por"  # the partial-order reduction (docs/reduction.md)
    NONE = "none"  # every interleaving


POR: Final = ReductionMode.POR
NONE: Final = ReductionMode.NONE
REDUCTIONS: Final = tuple(ReductionMode)
# Frontier worlds at which an exhaustive search moves to Ray workers. Each level there
# costs 10-16 ms of round trips on a 2-core machine, against about 45 us a world in one
# process: levels under a few hundred worlds are faster at home (docs/distributed.md).
MIN_WIDTH: Final = 512
# Worlds a `por` search stores unreduced before the reduction starts (`checker.late_start`):
# below this a search takes a tenth of a second either way, and the reduction's bookkeeping,
# learning and restarts cost more than the worlds it saves (head-on, 399 worlds: 1.12-1.19
# times the unreduced check's time; the station, 31 worlds: 1.2). 0: reduce from the first.
REDUCE_FROM: Final = 1_000


def choice_of(kind: type[StrEnum], allowed: Sequence[StrEnum] | None = None
              ) -> Callable[[str], StrEnum]:
    """An argparse `type` reading a member of `kind` by its name (of `allowed`, if given),
    refusing any other word in argparse's own terms, naming the choices."""
    choices = tuple(kind) if allowed is None else tuple(allowed)

    def parse(text: str) -> StrEnum:
        if text not in choices:
            raise argparse.ArgumentTypeError(f"invalid choice: {text!r} (choose from "
                                             f"{', '.join(choices)})")
        return kind(text)

    parse.__name__ = kind.__name__
    return parse


def add_check_arguments(p: argparse.ArgumentParser, *,
                        searches: Sequence[SearchOrder] = tuple(SearchOrder),
                        limits_only: bool = False) -> None:
    """Declare the options of the checks a command runs, for `check`, `sweep` and
    `experiment` alike (`searches`: the orders the command offers; `limits_only`: only
    --max-states and --max-time, for a command that fixes the rest). `SearchChoices.of`
    reads them back."""
    p.add_argument("--max-states", type=int, default=None, metavar="N",
                   help="stop a search after N distinct states, with no answer (default: "
                   "the scenario's check.max_states)")
    p.add_argument("--max-time", type=float, default=None, metavar="SECONDS",
                   help="stop a search after SECONDS, with no answer (default: the "
                   "scenario's check.max_time_s)")
    if limits_only:
        return
    p.add_argument("--max-depth", type=int, default=None, metavar="N",
                   help="do not expand worlds deeper than N steps (random: walk length)")
    p.add_argument("--search", type=choice_of(SearchOrder, searches), choices=tuple(searches),
                   default=None,
                   help="search order: bfs (shortest counterexample, default), dfs"
                   + (", or random walks" if SearchOrder.RANDOM in searches else "")
                   + "; not given, an unreduced search on --workers runs in a relaxed "
                   "order (same states and transitions, any counterexample)")
    p.add_argument("--reduction", type=choice_of(ReductionMode), choices=tuple(ReductionMode),
                   default=None,
                   help="partial-order reduction: por (explore one persistent set of "
                   "simultaneous events per world; same verdicts, far fewer states for "
                   "independent robots) or none (every interleaving). Default: por under ros, "
                   "none under rebeca (its counts are compared with RMC's). por starts once "
                   "the search has stored 1,000 worlds (a smaller search runs unreduced, "
                   "which is faster there), and steps aside where it would not pay. It turns "
                   "itself off, and says why in the summary, for settings it does not cover "
                   "(check.queue_bound, properties reading now, --search random, rebeca "
                   "node priorities)")
    p.add_argument("--fairness", type=choice_of(Fairness), choices=tuple(Fairness),
                   default=None,
                   help="what a counterexample to an eventually property may assume of lossy "
                   "channels: none (any cycle on which it never holds, even one that drops "
                   "the same message for ever) or weak (only a cycle on which every message "
                   "dropped is also handled; docs/finite-state.md). Default: check.fairness, "
                   "else none")
    p.add_argument("--no-contract-checks", dest="verify", action="store_false",
                   help="skip the node-contract checks that run by default (clocks and "
                   "random sources probed, attributes outside self.state compared, every "
                   "new handler run run twice and compared; 20-40%% of the search time "
                   "on c1a). A breach ends the check with one line naming node, handler, "
                   "what differed and the fix, exit 4")


@final
@dataclass(frozen=True)
class SearchChoices:
    """What `add_check_arguments` declared, as parsed (None: the scenario's, else the
    default); `fields()` are `CheckOptions` keyword arguments of the same names."""

    search: SearchOrder | None = None
    reduction: ReductionMode | None = None
    max_states: int | None = None
    max_time_s: float | None = None
    max_depth: int | None = None
    verify: bool = True
    fairness: Fairness | None = None

    @classmethod
    def of(cls, args: argparse.Namespace) -> SearchChoices:
        """The choices of parsed arguments (those a command did not declare: defaults)."""
        return cls(getattr(args, "search", None), getattr(args, "reduction", None),
                   args.max_states, args.max_time, getattr(args, "max_depth", None),
                   getattr(args, "verify", True), getattr(args, "fairness", None))

    def fields(self) -> dict[str, Any]:
        """The choices as keyword arguments of `CheckOptions`."""
        # fairness only when given: a sweep's cache keys (sweep.cache) of earlier runs stay
        fair = {} if self.fairness is None else {"fairness": self.fairness}
        return {"search": self.search, "reduction": self.reduction,
                "max_states": self.max_states, "max_time_s": self.max_time_s,
                "max_depth": self.max_depth, "verify": self.verify, **fair}


def _probability(text: str) -> float:
    value = float(text)
    if not 0 < value < 1:
        raise argparse.ArgumentTypeError(f"expected a probability in (0, 1), got {text}")
    return value


def add_statistical_arguments(p: argparse.ArgumentParser) -> None:
    """Add the statistical-checking and timing-model options to the `check` parser."""
    g = p.add_argument_group(
        "statistical checking (--statistical)",
        "Independent simulations in which every latency is drawn from a timing model and "
        "every ctx.choose uniformly; reports per property the probability of a violation "
        "within the horizon with a Clopper-Pearson interval. Exit 0: no violation seen "
        "(with --assert-below: accepted), 1: a violation seen (refused), 2: bad input "
        "(undecided), 4: a node breaks the node contract. The same --seed gives the same "
        "answer with any --workers.")
    g.add_argument("--statistical", action="store_true",
                   help="estimate probabilities by simulation instead of exploring every "
                   "interleaving")
    g.add_argument("--timing", default=None, metavar="FILE",
                   help="timing model (`twinfleet calibrate`; default: the scenario's "
                   "check.latency, each value equally likely, else the loopback model shipped "
                   "with twinfleet, said on the first line). Without --statistical, its "
                   "latency bounds become the exhaustive search's latency ranges and its "
                   "timer lateness check.timer_lateness (every value a branch)")
    g.add_argument("--simulations", type=int, default=None, metavar="N",
                   help="at most N simulations (default 1000; unbounded with --precision "
                   "or --assert-below, which stop by themselves)")
    g.add_argument("--horizon-ms", type=int, default=None, metavar="MS",
                   help="simulate up to this fleet time (default: live.horizon_s, else 60 s)")
    g.add_argument("--max-steps", type=int, default=1_000_000,
                   help="steps per simulation at most (default 1,000,000)")
    g.add_argument("--confidence", type=_probability, default=0.95,
                   help="confidence of the intervals (default 0.95)")
    g.add_argument("--precision", type=float, default=None, metavar="H",
                   help="stop once every interval's half-width is at most H")
    g.add_argument("--assert-below", type=_probability, default=None, metavar="P",
                   help="test 'P(some property violated) < P' by Wald's SPRT, stopping as "
                   "soon as it decides")
    g.add_argument("--indifference", type=_probability, default=None, metavar="D",
                   help="SPRT indifference region [P-D, P] (default D = P/2)")
    g.add_argument("--alpha", type=_probability, default=0.01,
                   help="SPRT: probability of accepting although P(violation) >= P "
                   "(default 0.01)")
    g.add_argument("--beta", type=_probability, default=0.01,
                   help="SPRT: probability of refusing although P(violation) <= P-D "
                   "(default 0.01)")
    g.add_argument("--traces-out", default="out", metavar="DIR",
                   help="directory for the traces of violating simulations (default out)")
    g.add_argument("--max-traces", type=int, default=3,
                   help="write at most this many violating simulations (default 3)")


def add_engine_arguments(p: argparse.ArgumentParser) -> None:
    """Add the options that spread a check over processes or machines (`checker.cluster`,
    `checker.parallel`)."""
    g = p.add_argument_group(
        "workers (the exhaustive search on Ray, --statistical simulations)",
        "The exhaustive search on several processes or machines gives the one-process "
        "states, transitions, verdict and trace length; the summary's engine line says "
        "where it ran (docs/distributed.md). With --checkpoint it is saved between two "
        "levels; --resume continues it on any number of workers, or in this process.")
    g.add_argument("--workers", type=int, default=1, metavar="N",
                   help="worker processes (default 1). Exhaustive search: N > 1 runs it on a "
                   "local Ray cluster this command starts and stops (127.0.0.1, no "
                   "dashboard, no usage statistics; needs pip install twinfleet[cluster]) "
                   "once its frontier is --min-width wide (levels of a few hundred worlds "
                   "or fewer are slower there: docs/distributed.md); --statistical: local "
                   "processes, or Ray tasks with --cluster")
    g.add_argument("--cluster", default=None, metavar="ADDRESS",
                   help="join the Ray cluster at ADDRESS (host:port of `ray start --head`; "
                   "RAY_AUTH_TOKEN must match the cluster's) instead of starting one; "
                   "docs/distributed.md")
    g.add_argument("--min-width", type=int, default=MIN_WIDTH, metavar="W",
                   help="exhaustive search with --workers/--cluster: stay in this process "
                   "until a BFS level holds W worlds, and come back when levels stay "
                   f"narrower (narrow searches never leave it; default {MIN_WIDTH}). The "
                   "workers start, once the search also found 50,000 states (a smaller "
                   "one ends before they are up), while it goes on here, and take it over "
                   "once up; 1: the whole search on the workers, waiting for them to start")
