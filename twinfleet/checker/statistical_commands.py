"""`twinfleet check --statistical`: the run behind the options `checker.options` adds.

`checker.commands` imports this module when the command runs, so that `twinfleet
--help` loads no more of the checker than its parser.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import TYPE_CHECKING

from twinfleet.runtime.contract.kinds import EXIT_BAD_INPUT, EXIT_CONTRACT_BREACH

if TYPE_CHECKING:
    from twinfleet.checker.statistical import StatisticalResult


def _progress(result: StatisticalResult) -> None:
    tty = sys.stderr.isatty()
    estimate = result.estimates()[-1]  # the same interval as the final table's
    rate = len(result.simulations) / result.elapsed_s if result.elapsed_s else 0.0
    print(f"{chr(13) if tty else ''}[check] {len(result.simulations):,} simulations  "
          f"{estimate.violations:,} violating  P {estimate.p:.4f} "
          f"[{estimate.low:.4f}, {estimate.high:.4f}]  {rate:,.1f} sim/s",
          file=sys.stderr, end="" if tty else "\n", flush=True)


def statistical_command(args: argparse.Namespace, bad_input: tuple[type[Exception], ...],
                        params: tuple[str, ...] = ()) -> int:
    """Run `check --statistical` for parsed arguments; return the exit code (`bad_input`:
    the errors that mean bad input, exit 2; `params`: the parameter overrides, read by
    `checker.commands` as for every other mode)."""
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
        beta=args.beta, workers=args.workers, cluster=args.cluster, timing=args.timing, traces_out=args.traces_out,
        max_traces=args.max_traces, max_time_s=args.max_time, verify=args.verify,
        params=params,
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

