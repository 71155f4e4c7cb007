"""The `check` and `replay` commands: argument parsing over `checker.driver` and `checker.trace`.

`twinfleet.cli` calls `register(subparsers)` for `check`; `replay` is
registered by `twinfleet.agreement.commands`, which adds `--live` to the
arguments `add_replay_arguments` defines here. `python -m twinfleet.checker
SCENARIO` runs `main()` here (both commands, no live replay). Exit codes: 0 holds
(or replay confirmed), 1 violated, 2 bad input, a limit reached before an answer,
or a replay that diverged, 4 a node breaks the node contract (one line on stderr).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from twinfleet.checker.options import (
    SearchChoices,
    Semantics,
    add_check_arguments,
    add_engine_arguments,
    add_statistical_arguments,
    choice_of,
)
from twinfleet.runtime.contract.kinds import EXIT_BAD_INPUT, EXIT_CONTRACT_BREACH, EXIT_FAILED
from twinfleet.runtime.scenario.overrides import add_override_arguments, override_words

if TYPE_CHECKING:
    from twinfleet.checker.driver import CheckResult
    from twinfleet.checker.outcome import SearchStatistics


def bad_input_errors() -> tuple[type[Exception], ...]:
    """The errors that mean bad input (exit 2); importing them loads the checker, so only
    a running command asks."""
    from twinfleet.checker.checkpoint import CheckpointError
    from twinfleet.checker.cluster import ClusterError
    from twinfleet.checker.properties import PropertyError
    from twinfleet.checker.timing import TimingError
    from twinfleet.runtime.contract.node import NodeDefinitionError
    from twinfleet.runtime.contract.tracefile import TraceError
    from twinfleet.runtime.scenario.spec import ScenarioError

    return (ScenarioError, PropertyError, NodeDefinitionError, TraceError, CheckpointError,
            TimingError, ClusterError)


def register(subparsers: Any) -> None:
    """Add the `check` subcommand to an argparse subparsers object."""
    p = subparsers.add_parser("check", help="explore every interleaving of a scenario",
                              description="Check a scenario's properties exhaustively "
                              "(exit 0 holds, 1 violated, 2 bad input or no answer, 4 a node "
                              "breaks the node contract: reads a clock or random, keeps state "
                              "outside self.state, state that cannot be encoded, a lambda as a "
                              "timer).")
    p.add_argument("scenario", nargs="?", default=None,
                   help="scenario YAML file, or the name of a shipped example (optional "
                        "with --resume)")
    add_override_arguments(p)  # the same overrides as `launch`, validated the same way
    add_check_arguments(p)  # the search options `sweep` and `experiment` declare too
    p.add_argument("--walks", type=int, default=100, help="number of random walks (--search random)")
    p.add_argument("--seed", type=int, default=None,
                   help="seed of the random walks (default: the scenario's seed)")
    p.add_argument("--semantics", type=choice_of(Semantics), choices=tuple(Semantics),
                   default=None,
                   help="message rules: ros (per-sender FIFO) or rebeca (RMC); default: scenario")
    p.add_argument("--trace-out", default=None,
                   help="where to write a counterexample trace (default: out/<name>.trace.json)")
    p.add_argument("--json", action="store_true", help="print the result as JSON on stdout")
    p.add_argument("--debug-state", action="store_true",
                   help="also compare every node attribute other than self.state by value "
                   "before and after each handler (finds in-place changes such as "
                   "self.seen.append(x); slow, turns off the transition cache)")
    p.add_argument("--check-determinism", action="store_true",
                   help="verify every transition, not only new handler runs (finds a "
                   "handler that reads a counter another handler keeps outside self.state; "
                   "slower: turns off the transition cache)")
    p.add_argument("--exact-states", action="store_true",
                   help="store 128-bit digests of full world encodings instead of 64-bit "
                   "digests (about 3x the memory per state; false merges ~n^2/2^129)")
    p.add_argument("--no-transition-cache", action="store_true",
                   help="re-run every handler instead of reusing the outcome of the same "
                   "(node state, event, time) (for comparison; same results, slower)")
    p.add_argument("--checkpoint", default=None, metavar="FILE",
                   help="save the search to FILE periodically and when it stops early "
                   "(a limit or Ctrl-C); continue it with --resume FILE. A checkpoint is a "
                   "Python pickle of the search (visited states, queue, node states): loading "
                   "one runs code, so it is trusted like code; resume only your own files")
    p.add_argument("--checkpoint-every", type=float, default=300.0, metavar="SECONDS",
                   help="seconds between periodic checkpoints (default 300)")
    p.add_argument("--resume", default=None, metavar="FILE",
                   help="continue the search saved in checkpoint FILE (and keep saving to it "
                   "unless --checkpoint names another file); FILE is a pickle, trusted like "
                   "code (see --checkpoint)")
    p.add_argument("--quiet", action="store_true", help="no progress line on stderr")
    p.add_argument("--strict", action="store_true",
                   help="lint warnings (nondeterminism sources, names nothing answers) fail the "
                        "check with exit 2 before it starts")
    add_statistical_arguments(p)
    add_engine_arguments(p)
    p.set_defaults(func=check_command)
    _register_trace(subparsers)


def _register_trace(subparsers: Any) -> None:
    """Add `trace show`: a counterexample step by step."""
    t = subparsers.add_parser("trace", help="read a counterexample trace",
                              description="Read a counterexample trace written by `check`.")
    sub = t.add_subparsers(dest="trace_command", required=True, metavar="ACTION")
    s = sub.add_parser("show", help="print a trace step by step",
                       description="Re-execute a trace on its scenario (checking every step's "
                       "world digest, as `replay` does) and print each step: time, node and "
                       "handler, the message it handled, the messages it sent, the states it "
                       "changed, its logs; the violated property last. Exit 0, or 2 when the "
                       "trace cannot be read or does not replay.")
    s.add_argument("trace", help="the trace file (e.g. out/<scenario>.trace.json)")
    s.add_argument("--json", action="store_true",
                   help="print the steps as one JSON document, for tools")
    s.set_defaults(func=trace_show_command)


def trace_show_command(args: argparse.Namespace) -> int:
    """Run `trace show` for parsed arguments; return the exit code."""
    from twinfleet.checker.driver import system_for_trace
    from twinfleet.checker.trace import NondeterminismError
    from twinfleet.checker.trace_show import text_lines, walk
    from twinfleet.runtime.contract.tracefile import load_trace

    try:
        trace = load_trace(args.trace)
        system, _ = system_for_trace(trace)
        shown = walk(system, trace)
    except (*bad_input_errors(), NondeterminismError) as exc:  # type: ignore[misc]
        print(f"twinfleet trace show: {args.trace}: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        print(f"twinfleet trace show: {args.trace}: the trace does not fit its scenario "
              f"({type(exc).__name__}: {exc})", file=sys.stderr)
        return EXIT_BAD_INPUT
    if args.json:
        print(json.dumps(shown.to_json(), indent=1, default=str))
    else:
        print("\n".join(text_lines(shown)))
    return 0


def add_replay_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add the `replay` subcommand (offline replay of a trace) and return its parser."""
    r = subparsers.add_parser("replay", help="re-execute a counterexample trace",
                              description="Re-run a trace written by `check`, verify every "
                              "step's world digest and confirm the violation (exit 1 when "
                              "confirmed, 2 when not or when the replay diverges).")
    r.add_argument("trace", help="trace JSON file written by `twinfleet check`")
    r.add_argument("--quiet", action="store_true", help="print only the verdict line")
    r.set_defaults(func=replay_command)
    return r


def _progress(stats: SearchStatistics) -> None:
    tty = sys.stderr.isatty()
    lead = "\r" if tty else ""
    print(f"{lead}[check] states {stats.states:,}  "
          f"transitions {stats.transitions:,}  {stats.states_per_s:,.0f} states/s  "
          f"depth {stats.depth}  frontier {stats.frontier:,}  mem {stats.peak_rss_mb:.0f} MB"
          + (f"  (restart {stats.restarts}: the reduction learned a send and searches again "
             "from scratch; counts since)" if stats.restarts else "")
          + ("  growing: " + ", ".join(n.short() for n in stats.growth) if stats.growth
             else ""), file=sys.stderr, end="" if tty else "\n", flush=True)


def _report_line(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def one_blas_thread() -> None:
    """Ask OpenBLAS (numpy's linear algebra) for one thread, unless the user chose a number.

    A search runs handlers one at a time on one thread (and a worker per core for more);
    OpenBLAS' own threads start with numpy's import and busy-wait there for a while, and
    again after every call they share: 0.04-0.12 s of a core on c1a_rebeca, which uses no
    linear algebra worth a thread. Effective only before numpy's first import.
    """
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def check_command(args: argparse.Namespace) -> int:
    """Run `check` for parsed arguments; return the exit code."""
    one_blas_thread()
    if args.workers < 1 or args.min_width < 1:
        print("twinfleet check: --workers and --min-width must be at least 1", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:  # read once, before any mode branches off: every mode checks what launch runs
        params = tuple(override_words("check", args.overrides, args.param))
    except ValueError as exc:
        print(f"twinfleet {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    if args.statistical:
        from twinfleet.checker.statistical_commands import statistical_command

        return statistical_command(args, bad_input_errors(), params)
    if args.scenario is None and args.resume is None:
        print("twinfleet check: give a scenario file, or --resume CHECKPOINT", file=sys.stderr)
        return EXIT_BAD_INPUT
    from twinfleet.checker.diagnosis import ContractBreachError
    from twinfleet.checker.driver import CheckOptions, check

    if args.strict and args.scenario is not None and _lint_fails(args, params):
        return EXIT_BAD_INPUT
    stem = Path(args.scenario or args.resume).stem
    trace_out = args.trace_out or str(Path("out") / f"{stem}.trace.json")
    options = CheckOptions(**SearchChoices.of(args).fields(), walks=args.walks, seed=args.seed,
                           semantics=args.semantics, trace_out=trace_out,
                           debug_state=args.debug_state, exact_states=args.exact_states,
                           check_determinism=args.check_determinism,
                           transition_cache=not args.no_transition_cache,
                           checkpoint=args.checkpoint, checkpoint_every_s=args.checkpoint_every,
                           resume=args.resume, timing=args.timing,
                           params=params, workers=args.workers, cluster=args.cluster,
                           min_width=args.min_width,
                           report=None if args.quiet or args.json else _report_line,
                           progress=None if args.quiet or args.json else _progress)
    try:
        result = check(args.scenario, options)
    except bad_input_errors() as exc:
        print(f"twinfleet check: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except ContractBreachError as exc:  # before any search: an initial state (checker.topology)
        print(f"twinfleet check: {exc}", file=sys.stderr)
        return EXIT_CONTRACT_BREACH
    if options.progress is not None and sys.stderr.isatty():
        print(file=sys.stderr)
    if not args.json:
        for line in result.warnings:
            print(line, file=sys.stderr)
    _report(result, as_json=args.json)
    return result.exit_code


def _lint_fails(args: argparse.Namespace, params: tuple[str, ...]) -> bool:
    """With --strict: print the scenario's lint warnings and say they fail the check."""
    from twinfleet.checker.driver import load
    from twinfleet.runtime.scenario.lint import lint_scenario

    try:
        warnings = lint_scenario(load(args.scenario, semantics=args.semantics,
                                      params=params))
    except bad_input_errors():
        return False  # the check itself reports a scenario it cannot load
    for warning in warnings:
        print(warning, file=sys.stderr)
    if warnings:
        print(f"twinfleet check: --strict: {len(warnings)} lint warning(s) fail the check",
              file=sys.stderr)
    return bool(warnings)


def _report(result: CheckResult, *, as_json: bool) -> None:
    if as_json:
        print(json.dumps(result.to_json(), indent=1))
        return
    if result.breach is not None:  # no verdict to summarise: one line, exit 4
        print(f"twinfleet check: {result.breach}", file=sys.stderr)
        return
    print(result.summary())
    if result.exit_code == EXIT_BAD_INPUT:
        print(f"exit 2: no answer ({result.reason})")


def replay_command(args: argparse.Namespace) -> int:
    """Run `replay` for parsed arguments; return the exit code."""
    from twinfleet.checker.driver import system_for_trace
    from twinfleet.checker.trace import NondeterminismError, replay
    from twinfleet.runtime.contract.tracefile import code_changes, load_trace

    changed: list[str] = []
    try:
        trace = load_trace(args.trace)
        if trace.get("scenario_changed"):  # say so before a replay that may then diverge
            print(f"twinfleet replay: warning: {trace['scenario_changed']}", file=sys.stderr)
        system, props = system_for_trace(trace)
        changed = code_changes(trace, {cfg.name: cfg.cls for cfg in system.scenario.nodes})
        for line in changed:
            print(f"twinfleet replay: warning: {line}", file=sys.stderr)
        result = replay(system, trace, props)
    # mypy reads no exception types out of a starred tuple (they are all Exception classes)
    except (*bad_input_errors(), NondeterminismError) as exc:  # type: ignore[misc]
        print(f"twinfleet replay: {args.trace}: {''.join(f'{c}; ' for c in changed)}{exc}",
              file=sys.stderr)
        return EXIT_BAD_INPUT
    except (KeyError, TypeError, ValueError, IndexError) as exc:  # fits no node of the scenario
        print(f"twinfleet replay: {args.trace}: {''.join(f'{c}; ' for c in changed)}the trace "
              f"does not fit its scenario ({type(exc).__name__}: {exc})", file=sys.stderr)
        return EXIT_BAD_INPUT
    if result.confirmed:
        print(f"replay confirmed: {result.property} violated after {result.steps} steps "
              f"({result.message})")
        return EXIT_FAILED
    cause = "".join(f"{line}; " for line in changed)  # the likely cause, first
    print(f"replay NOT confirmed: {cause}{result.property}: {result.message}")
    return EXIT_BAD_INPUT  # not confirmed: no answer (module docstring)


def main(argv: Sequence[str] | None = None) -> int:
    """`python -m twinfleet.checker [check|replay] ...`; a bare scenario path means `check`."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] not in ("check", "replay", "-h", "--help"):
        argv.insert(0, "check")
    parser = argparse.ArgumentParser(prog="python -m twinfleet.checker",
                                     description="twinfleet's model checker")
    sub = parser.add_subparsers(dest="command", required=True)
    register(sub)
    add_replay_parser(sub)
    args = parser.parse_args(argv)
    return int(args.func(args))
