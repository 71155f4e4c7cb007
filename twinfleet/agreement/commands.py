"""The agreement layer's commands: `validate`, `calibrate` and `replay` (with `--live`).

`register(subparsers)` adds them to `twinfleet` (`twinfleet.cli`). `replay` is the
checker's offline replay (`checker.commands.add_replay_parser`) plus `--live`, a
re-enactment on the real processes, which needs both drivers and so lives in this layer.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from twinfleet.checker.commands import add_replay_parser, replay_command
from twinfleet.checker.options import Semantics
from twinfleet.runtime.contract.kinds import EXIT_BAD_INPUT, EXIT_OK
from twinfleet.runtime.scenario.overrides import add_override_arguments


def register(subparsers: Any) -> None:
    """Add `validate`, `replay` and `calibrate` to an argparse subparsers object (imports
    nothing heavy: the checker and the live runtime are loaded when a command runs)."""
    _validate_parser(subparsers)
    _replay_parser(subparsers)
    _calibrate_parser(subparsers)


def _calibrate_parser(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "calibrate", help="fit a timing model (latency, timer lateness) from live event logs",
        description="Fit a timing model from event logs written by `twinfleet launch "
        "--record-events`: per topic or service the delivery latency (handling time minus "
        "send stamp, fleet ms), pooled as the default, and timer lateness; the machine and "
        "the time scale are recorded. `twinfleet check --timing FILE` uses it (exit 2: bad "
        "input).")
    p.add_argument("events", nargs="+", help="event log files (JSON lines)")
    p.add_argument("-o", "--output", default="timing.yaml",
                   help="the timing model file to write (default timing.yaml)")
    p.add_argument("--min-samples", type=int, default=30,
                   help="a channel with fewer latencies is covered by the default "
                   "histogram only (default 30)")
    p.add_argument("--startup-ms", type=int, default=20, metavar="MS",
                   help="messages sent in the fleet's first MS fleet ms get a latency "
                   "histogram of their own, used for the first MS ms of every simulation: "
                   "a fleet's first messages take several times longer (0: none; default 20)")
    p.add_argument("--levels", type=int, default=1, metavar="K",
                   help="load levels: each event log is one run; the runs, sorted by their "
                   "mean latency, are cut into K groups, and a simulation draws its group "
                   "(by its share of the runs) before drawing any latency from it, as a "
                   "live run's latencies share its machine's load (1: none, the pooled "
                   "histograms; default 1)")
    p.set_defaults(func=calibrate_command)


def calibrate_command(args: argparse.Namespace) -> int:
    """Run `calibrate`; return the exit code."""
    from twinfleet.agreement.calibrate import calibrate
    from twinfleet.checker.timing import TimingError, save_timing

    try:
        model = calibrate(args.events, min_samples=args.min_samples,
                          startup_ms=args.startup_ms, levels=args.levels)
    except TimingError as exc:
        print(f"twinfleet calibrate: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    save_timing(model, args.output)
    print(f"{args.output}: {model.describe()} ({model.default.samples:,} latencies)")
    return EXIT_OK


def cmd_validate(args: argparse.Namespace) -> int:
    """`twinfleet validate`: is a recorded live run a path of the checker's transitions?"""
    from twinfleet.agreement.validate import validate_command

    return validate_command(args)


def _validate_parser(sub: Any) -> None:
    p = sub.add_parser("validate", help="check that a live run recorded with `launch "
                                        "--record-events` is a path of the checker's transitions",
                       description="Find an interleaving of the nodes' logged events that the "
                       "checker's transition relation can run, with the same arguments, "
                       "ctx.choose answers and node states; report the first step it cannot "
                       "explain. The first line is the verdict: VALID (exit 0) a path of the "
                       "checker's exact model, NOT EXPLAINED (exit 1) a step the checker "
                       "cannot take, OUTSIDE THE MODEL (exit 3) a path only if timing is "
                       "ignored (a property broken on it is no counterexample the checker "
                       "missed); exit 2 bad input.")
    p.add_argument("events", help="event log written by `twinfleet launch --record-events FILE`")
    p.add_argument("scenario", help="the scenario YAML the run used")
    add_override_arguments(p)  # the overrides the run was launched with
    p.add_argument("--tolerance-ms", type=int, default=None, metavar="T",
                   help="also judge timing: events whose model times differ by at most T ms may "
                        "run in either order; 0 = the checker's exact rules (default: judge "
                        "order and state only, and report the first step outside the exact "
                        "timing rules and the tolerance this run needs)")
    p.add_argument("--window-ms", type=int, default=5, metavar="W",
                   help="live events of different nodes dispatched within W ms of each other "
                        "may be taken in either order (default: %(default)s)")
    p.add_argument("--semantics", choices=[s.value for s in Semantics], default=None,
                   help="checker message rules (default: the scenario's)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.set_defaults(func=cmd_validate)


def _replay_parser(sub: Any) -> None:
    """`replay TRACE [--live]`: the checker's replay command, plus a live re-enactment."""
    replay = add_replay_parser(sub)
    replay.add_argument("--live", action="store_true",
                        help="re-enact the trace on the real multi-process fleet over Zenoh: a "
                             "coordinator grants each node's deliveries, timers and ctx.choose "
                             "answers in the trace's order (logical time, as fast as the "
                             "processes go) and confirms the violation on the live processes "
                             "(exit 1 confirmed, 2 not)")
    replay.add_argument("--cycles", type=int, default=2, metavar="N",
                        help="with --live and a lasso trace (a liveness violation): go round its "
                             "cycle N more times, checking that the live nodes come back to the "
                             "same states every round (default: %(default)s)")
    replay.set_defaults(func=_replay_or_live)


def _replay_or_live(args: argparse.Namespace) -> int:
    if not args.live:
        return replay_command(args)
    from twinfleet.agreement.live_replay import live_replay_command

    return live_replay_command(args)
