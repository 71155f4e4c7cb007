"""The `--statistical` and `--timing` options of `twinfleet check`, and the statistical run.

Kept apart from `checker.commands` so that the parser stays light: the engine
(`checker.statistical`) is imported when the command runs.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import TYPE_CHECKING

from twinfleet.runtime.contract.kinds import EXIT_BAD_INPUT, EXIT_CONTRACT_BREACH

if TYPE_CHECKING:
    from twinfleet.checker.statistical import StatisticalResult


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
                   help="timing model (`twinfleet calibrate`; default: the loopback model "
                   "shipped with twinfleet). Without --statistical, its latency bounds become "
                   "the exhaustive search's latency ranges (every value a branch)")
    g.add_argument("--simulations", type=int, default=None, metavar="N",
                   help="at most N simulations (default 1000; unbounded with --precision "
                   "or --assert-below, which stop by themselves)")
    g.add_argument("--horizon-ms", type=int, default=None, metavar="MS",
                   help="simulate up to this fleet time (default: live.timeout_s, else 60 s)")
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
    g.add_argument("--workers", type=int, default=1, metavar="N",
                   help="local worker processes for the simulations (default 1)")
    g.add_argument("--traces-out", default="out", metavar="DIR",
                   help="directory for the traces of violating simulations (default out)")
    g.add_argument("--max-traces", type=int, default=3,
                   help="write at most this many violating simulations (default 3)")


def _progress(result: StatisticalResult) -> None:
    tty = sys.stderr.isatty()
    estimate = result.estimates(exact=False)[-1]
    rate = len(result.simulations) / result.elapsed_s if result.elapsed_s else 0.0
    print(f"{chr(13) if tty else ''}[check] {len(result.simulations):,} simulations  "
          f"{estimate.violations:,} violating  P {estimate.p:.4f} "
          f"[{estimate.low:.4f}, {estimate.high:.4f}]  {rate:,.1f} sim/s",
          file=sys.stderr, end="" if tty else "\n", flush=True)


def statistical_command(args: argparse.Namespace,
                        bad_input: tuple[type[Exception], ...]) -> int:
    """Run `check --statistical` for parsed arguments; return the exit code (`bad_input`:
    the errors that mean bad input, exit 2)."""
    from twinfleet.checker.simulate import ContractBreach
    from twinfleet.checker.statistical import StatisticalOptions, check_statistical
    from twinfleet.checker.timing import TimingError

    if args.scenario is None:
        print("twinfleet check: --statistical needs a scenario file", file=sys.stderr)
        return EXIT_BAD_INPUT
    quiet = args.quiet or args.json
    options = StatisticalOptions(
        simulations=args.simulations, seed=args.seed, horizon_ms=args.horizon_ms,
        max_steps=args.max_steps, confidence=args.confidence, precision=args.precision,
        assert_below=args.assert_below, indifference=args.indifference, alpha=args.alpha,
        beta=args.beta, workers=args.workers, timing=args.timing, traces_out=args.traces_out,
        max_traces=args.max_traces, max_time_s=args.max_time, verify=args.verify,
        profile=args.profile,
        semantics=args.semantics, progress=None if quiet else _progress)
    try:
        result = check_statistical(args.scenario, options)
    except (*bad_input, TimingError) as exc:  # type: ignore[misc]
        print(f"twinfleet check: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except ValueError as exc:  # the SPRT's parameters
        print(f"twinfleet check: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except ContractBreach as exc:
        print(f"twinfleet check: {exc}", file=sys.stderr)
        return EXIT_CONTRACT_BREACH
    if not quiet and sys.stderr.isatty():
        print(file=sys.stderr)
    print(json.dumps(result.to_json(), indent=1) if args.json else result.summary())
    return result.exit_code

