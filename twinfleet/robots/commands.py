"""The robot case study's command: `twinfleet experiment`, the paper's Table 4/5.

`register(subparsers)` adds it to `twinfleet` (`twinfleet.cli`); `main()` is
`python -m twinfleet.robots`.

    twinfleet experiment SCENARIO... [--runs N] [--time-scale K]
                         [--semantics both|ros|rebeca] [--out DIR] [--jobs 1]
                         [--predict N] [--timing FILE] [--confidence C] [--workers N]

Exit codes: 0 done, and no live run contradicted a checker verdict; 1 a live
run did what the checker says cannot happen (a collision in a scenario the
checker proved collision-free, say); 2 bad input; 130 interrupted (the
outputs written so far are kept).
"""

from __future__ import annotations

import argparse
import shlex
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from twinfleet.checker.options import Semantics, add_check_arguments
from twinfleet.robots import DEFAULT_TIME_SCALE, EXAMPLES
from twinfleet.robots.table import to_markdown
from twinfleet.runtime.contract.kinds import (
    EXIT_BAD_INPUT,
    EXIT_FAILED,
    EXIT_INTERRUPTED,
    EXIT_OK,
)
from twinfleet.runtime.scenario.examples import add_examples
from twinfleet.runtime.scenario.overrides import (
    add_override_arguments,
    override_words,
    split_words,
)

_SEMANTICS = {"both": (Semantics.ROS, Semantics.REBECA), **{s.value: (s,) for s in Semantics}}


def register(subparsers: Any) -> None:
    """Add `experiment` to an argparse subparsers object (imports nothing heavy)."""
    p = subparsers.add_parser(
        "experiment", help="the paper's Table 4/5: checker verdicts and N live runs per scenario",
        description="For each scenario: run the checker (both semantics by default) and N live "
        "runs with seeds S, S+1, ..., then print the paper's Table 4/5 rows with the paper's own "
        "figures beside ours, and write them as Markdown and CSV into --out.")
    p.add_argument("scenarios", nargs="+", metavar="SCENARIO [NAME:=VALUE]",
                   help="scenario YAML files, and parameter overrides for all of them "
                   "(r1.speed:=0.4, as `check` takes them)")
    add_override_arguments(p, words=False)
    p.add_argument("--runs", type=int, default=20, metavar="N",
                   help="live runs per scenario; 0 runs the checker only (default: %(default)s)")
    p.add_argument("--time-scale", type=float, default=DEFAULT_TIME_SCALE, metavar="K",
                   help="live fleet time K times faster than wall time (default: %(default)g, "
                        "measured in docs/experiment.md)")
    p.add_argument("--semantics", choices=tuple(_SEMANTICS), default="both",
                   help="checker message rules to run (default: %(default)s)")
    p.add_argument("--out", default="out/experiment", metavar="DIR",
                   help="where experiment.md/.csv/.json, traces/ and logs/ go "
                        "(default: %(default)s)")
    p.add_argument("--jobs", type=int, default=1, metavar="1",
                   help="only 1: live runs are sequential so that no fleet shares the CPU with "
                        "another (timing is what is being measured)")
    p.add_argument("--seed", type=int, default=None, metavar="S",
                   help="seed of the first live run (default: the scenario's seed)")
    add_check_arguments(p, limits_only=True)  # as `check` declares them
    p.add_argument("--horizon", type=float, default=180.0, metavar="S",
                   help="fleet seconds a live run may last before it counts as not arrived "
                        "(default: %(default)g)")
    p.add_argument("--keep-going", action="store_true",
                   help="do not end a live run at its first collision")
    p.add_argument("--predict", type=int, default=100, metavar="N",
                   help="simulations (check --statistical, ros rules, until the outcome is "
                        "known) estimating P(a live run passes) per scenario; 0: no prediction "
                        "(default: %(default)s)")
    p.add_argument("--timing", default=None, metavar="FILE",
                   help="timing model of the prediction (`twinfleet calibrate`), stretched to "
                        "--time-scale (default: the loopback model shipped with twinfleet)")
    p.add_argument("--confidence", type=float, default=0.99, metavar="C",
                   help="confidence of the predicted interval (default: %(default)g)")
    p.add_argument("--workers", type=int, default=1, metavar="N",
                   help="local processes for the prediction's simulations (live runs are "
                        "always one at a time; default: %(default)s)")
    p.set_defaults(func=experiment_command)


def experiment_command(args: argparse.Namespace) -> int:
    """Run `experiment` for parsed arguments; return the exit code."""
    from twinfleet.checker.commands import bad_input_errors
    from twinfleet.robots.experiment import ExperimentOptions, run_experiment

    if args.jobs != 1:
        print("twinfleet experiment: --jobs: only 1 is supported; live fleets run one at a "
              "time so that their timing is not disturbed", file=sys.stderr)
        return EXIT_BAD_INPUT
    if args.runs < 0 or args.time_scale <= 0 or args.predict < 0 or args.workers < 1:
        print("twinfleet experiment: --runs and --predict must be >= 0, --time-scale > 0 and "
              "--workers >= 1", file=sys.stderr)
        return EXIT_BAD_INPUT
    if not 0 < args.confidence < 1:
        print("twinfleet experiment: --confidence must lie in (0, 1)", file=sys.stderr)
        return EXIT_BAD_INPUT
    if args.timing is not None:
        from twinfleet.checker.timing import TimingError, load_timing

        try:
            load_timing(args.timing)
        except TimingError as exc:
            print(f"twinfleet experiment: --timing: {exc}", file=sys.stderr)
            return EXIT_BAD_INPUT
    scenarios, words = split_words(args.scenarios)
    try:
        params = tuple(override_words("experiment", words, args.param))
    except ValueError as exc:
        print(f"twinfleet {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    if not scenarios:
        print("twinfleet experiment: give at least one scenario file", file=sys.stderr)
        return EXIT_BAD_INPUT
    options = ExperimentOptions(runs=args.runs, time_scale=args.time_scale,
                                semantics=_SEMANTICS[args.semantics], out=Path(args.out),
                                seed=args.seed, max_states=args.max_states,
                                max_time_s=args.max_time, horizon_s=args.horizon,
                                stop_on_collision=not args.keep_going, predict=args.predict,
                                timing=args.timing, confidence=args.confidence,
                                workers=args.workers, params=params)
    command = command_line(args)
    bad_input: tuple[type[Exception], ...] = (*bad_input_errors(), ValueError)
    try:
        exp = run_experiment(scenarios, options, command=command)
    except bad_input as exc:
        print(f"twinfleet experiment: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    print(to_markdown(exp.rows, options.semantics), end="")
    print(f"wrote {options.out / 'experiment.md'}, {options.out / 'experiment.csv'}, "
          f"{options.out / 'experiment.json'}; node output in {options.out / 'logs'}")
    if exp.interrupted:  # a live fleet takes the signal itself: SIGTERM is 143 there too
        from twinfleet.runtime.fleet.fleet_result import signal_exit_code

        return signal_exit_code(exp.stopped_by) or EXIT_INTERRUPTED
    return EXIT_FAILED if exp.contradictions else EXIT_OK


def command_line(args: argparse.Namespace) -> str:
    """The `twinfleet experiment` command that reproduces these arguments, every option spelled."""
    words = ["twinfleet", "experiment", *args.scenarios, *(f"--param={p}" for p in args.param),
             "--runs", str(args.runs),
             "--time-scale", f"{args.time_scale:g}", "--semantics", args.semantics,
             "--out", args.out]
    for flag, value in (("--seed", args.seed), ("--max-states", args.max_states),
                        ("--max-time", args.max_time)):
        if value is not None:
            words += [flag, f"{value:g}" if isinstance(value, float) else str(value)]
    if args.horizon != 180.0:
        words += ["--horizon", f"{args.horizon:g}"]
    if args.keep_going:
        words.append("--keep-going")
    words += ["--predict", str(args.predict), "--confidence", f"{args.confidence:g}"]
    if args.timing is not None:
        words += ["--timing", args.timing]
    if args.workers != 1:
        words += ["--workers", str(args.workers)]
    return " ".join(shlex.quote(w) for w in words)


def main(argv: Sequence[str] | None = None) -> int:
    """`python -m twinfleet.robots [experiment] SCENARIO... [options]`."""
    add_examples(EXAMPLES)  # as `twinfleet experiment` finds them
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] not in ("experiment", "-h", "--help"):
        argv.insert(0, "experiment")
    parser = argparse.ArgumentParser(prog="python -m twinfleet.robots",
                                     description="the robot case study's experiment")
    register(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return int(args.func(args))
