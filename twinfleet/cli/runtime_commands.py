"""The live runtime's commands: launch and examples (and, registered from here, the ROS 2-style
monitors of `cli.monitor_commands`, record, play, export, bag, view and foxglove).

    twinfleet launch SCENARIO [NODE.NAME:=VALUE ...] [--param NODE.NAME=VALUE] [--time-scale K]
                              [--timeout S] [--seed S] [--runs N] [--connect EP] [--listen EP]
    twinfleet examples [--copy NAME [DIR]]
    twinfleet node list|info     twinfleet topic list|info|type|echo|hz|pub
    twinfleet service list|type|call   twinfleet param list|get   twinfleet interface list|show
    twinfleet view [--port P] [--trace FILE]      twinfleet foxglove [--port P]

SCENARIO is a scenario file or the name of a shipped example (`twinfleet examples`
lists them). Monitors find the fleet in the fleet registry unless --connect is
given (`runtime.access.connection.connection`). `register(subparsers)` adds the commands to
the `twinfleet` command line (`twinfleet.cli`); `record`, `play`, `export` and
`bag` come from `cli.recording_commands`, `view` and `foxglove` from
`cli.viewer_commands`. Every command imports its engine
when it runs.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from twinfleet.cli import monitor_commands, recording_commands, viewer_commands
from twinfleet.ros2.commands import add_launch_ros2_arguments, launch_bridge
from twinfleet.runtime.access.connection import (
    CommandError,
    error_prefix,
)
from twinfleet.runtime.scenario.overrides import add_override_arguments, override_words


def register(sub: argparse._SubParsersAction) -> None:
    """Add the live runtime's subcommands to the `twinfleet` command line."""
    _launch_parser(sub)
    monitor_commands.register(sub)
    _examples_parser(sub)
    recording_commands.register(sub)
    viewer_commands.register(sub)


def cmd_launch(args: argparse.Namespace) -> int:
    """`twinfleet launch`: validate, run the fleet `--runs` times, print summaries."""
    params = launch_params(args)
    auth = _launch_access(args)
    scenario = _launchable(args, params)
    if scenario is None:
        return 2
    import zenoh

    from twinfleet.runtime.fleet.fleet_result import runs_summary
    from twinfleet.runtime.fleet.launcher import (
        FleetConflict,
        LaunchOptions,
        format_result,
        run_fleet,
    )
    bridge = launch_bridge(args, scenario)

    worst, codes = 0, []
    for run in range(args.runs):
        seed = (args.seed if args.seed is not None else scenario.seed) + run
        if args.runs > 1:
            print(f"[launcher] run {run + 1}/{args.runs} (seed {seed})", flush=True)
        try:
            options = LaunchOptions(
                time_scale=args.time_scale, timeout_s=args.timeout, seed=seed,
                connect=args.connect, listen=args.listen, run_record=args.record_run,
                record_events=_events_path(args, run), params=params, auth=auth,
                bridge=bridge is not None, accept_recorded=args.accept_recorded,
                node_args=["--verbose"] if args.verbose else [],
                until_settled=args.until_settled or None,
                until_violation=args.stop_on_violation or None)
            import asyncio  # here: the other commands (check) never start a loop

            result = asyncio.run(run_fleet(scenario, options, driver=bridge))
        except FleetConflict as exc:
            raise CommandError(str(exc)) from None
        except ValueError as exc:  # e.g. a bad TWINFLEET_ZENOH_CONFIG_OVERRIDE
            print(f"{error_prefix(args)} {exc}", file=sys.stderr)
            return 2
        except (OSError, zenoh.ZError) as exc:  # e.g. a --listen port in use
            raise CommandError(router_error(args, exc, auth)) from None
        for line in format_result(result):
            print(f"[launcher] {line}", flush=True)
        worst = _worse(worst, result.exit_code)
        codes.append(result.exit_code)
        if result.interrupted:
            break
    if args.runs > 1:
        print(f"[launcher] {runs_summary(scenario.name, codes, args.runs)}", flush=True)
    return worst


def _launchable(args: argparse.Namespace, params: Any) -> Any:
    """The scenario to launch, its lint warnings printed; None (after a one-line error)
    when it does not load, names a field no state has, or `--strict` refuses a warning."""
    from twinfleet.runtime.scenario.lint import lint_scenario
    from twinfleet.runtime.scenario.overrides import load_with_params
    from twinfleet.runtime.scenario.property_fields import check_property_fields
    from twinfleet.runtime.scenario.spec import ScenarioError

    try:
        scenario = load_with_params(args.scenario, params)
        check_property_fields(scenario)  # a misspelt field stops here, before any process
    except ScenarioError as exc:
        print(f"{error_prefix(args)} {exc}", file=sys.stderr)
        return None
    warnings = lint_scenario(scenario)  # nondeterminism sources, names nothing answers
    for warning in warnings:
        print(warning, file=sys.stderr)
    if warnings and args.strict:
        print(f"{error_prefix(args)} --strict: {len(warnings)} lint warning(s) fail the run; "
              "nothing was started", file=sys.stderr)
        return None
    return scenario


def _launch_access(args: argparse.Namespace) -> Any:
    """The credentials a launch joins with (`--credentials`), after refusing a --listen
    address that would expose the fleet unencrypted."""
    from twinfleet.runtime.access.fleetauth import (
        CredentialsError,
        listen_problem,
        read_credentials,
    )

    problem = listen_problem(args.listen, insecure=args.insecure_listen) if args.listen else None
    if problem:
        raise CommandError(problem)
    try:
        return read_credentials(args.credentials)[1] if args.credentials else None
    except CredentialsError as exc:
        raise CommandError(str(exc)) from None


_SEVERITY = (0, 3, 2, 1, 130)  # ok < inconclusive < bad input < failed < interrupted


def _worse(a: int, b: int) -> int:
    """The more severe of two runs' exit codes (an unknown code counts as failed)."""
    rank = {code: i for i, code in enumerate(_SEVERITY)}
    return max(a, b, key=lambda c: rank.get(c, rank[1]))


def cmd_examples(args: argparse.Namespace) -> int:
    """`twinfleet examples`: list the shipped scenarios, or copy one (and its map) to edit."""
    from twinfleet.runtime.scenario.examples import ExampleError, describe, shipped_scenarios
    from twinfleet.runtime.scenario.files import copy_example

    if args.copy is None:
        if args.dir is not None:
            print(f"{error_prefix(args)} a directory is given only with --copy NAME", file=sys.stderr)
            return 2
        shipped = shipped_scenarios()
        width = max(map(len, shipped))
        for name, path in shipped.items():
            print(f"{name:<{width}}  {describe(path)}")
        print("\nrun one with `twinfleet launch NAME` or `twinfleet check NAME`; "
              "edit a copy: `twinfleet examples --copy NAME [DIR]`")
        return 0
    from twinfleet.runtime.scenario.spec import ScenarioError, load_scenario

    try:
        files = copy_example(args.copy, args.dir or ".")
        load_scenario(files[0][0])  # the copy must load as it is
    except (ExampleError, ScenarioError, OSError) as exc:
        print(f"{error_prefix(args)} {exc}", file=sys.stderr)
        return 2
    for path, written in files:
        print(f"{'wrote' if written else 'kept existing'} {path}")
    return 0


def launch_params(args: argparse.Namespace) -> list[str]:
    """The launch's parameter overrides: ``NAME:=VALUE`` words, then ``--param NAME=VALUE``."""
    try:
        return override_words("launch", args.overrides, args.param)
    except ValueError as exc:
        raise CommandError(str(exc)) from None


def router_error(args: argparse.Namespace, exc: Exception, auth: Any = None) -> str:
    """One line for a router that cannot be opened or joined (e.g. a --listen port in use)."""
    from twinfleet.runtime.access.connection import unreachable_hint, zenoh_error_text

    where = f"--connect {args.connect}" if args.connect else (
        f"--listen {args.listen}" if args.listen else "the embedded router")
    hint = f" ({unreachable_hint(args.connect, auth)})" if args.connect else ""
    return f"cannot open {where}: {zenoh_error_text(exc)}{hint}"


def _events_path(args: argparse.Namespace, run: int) -> str | None:
    """Where run `run` of `launch --record-events FILE` writes: FILE, or FILE.<k> with --runs."""
    if not args.record_events or args.runs == 1:
        return args.record_events
    return f"{args.record_events}.{run + 1}"


def _launch_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("launch", help="run a scenario live: a router plus one process per node",
                       description="Run a scenario live: an embedded Zenoh router plus one process "
                       "per node. The scenario's properties are judged on the running fleet "
                       "(runtime verification over the states the nodes report); the run ends "
                       "with `result: PASSED` (exit 0), `FAILED` and the property violated (1), "
                       "`INCONCLUSIVE` and why (3: a node dropped samples or stalled), "
                       "`CONTRACT BREACH` (4: a handler broke the node contract, as `check` "
                       "would say, e.g. published a type its topic does not carry), "
                       "or `interrupted` (130, Ctrl-C).")
    p.add_argument("scenario", help="scenario YAML file, or the name of a shipped example "
                                    "(twinfleet examples lists them)")
    add_override_arguments(p)
    p.add_argument("--time-scale", type=float, default=None, metavar="K",
                   help="run fleet time K times faster than wall time (default: live.time_scale or 1)")
    p.add_argument("--strict", action="store_true",
                   help="lint warnings fail the run with exit 2 before anything starts")
    p.add_argument("--until-settled", action="store_true",
                   help="end the run once every eventually property has held (as the scenario's "
                        "live.stop: settled does); each one's time of holding is printed anyway")
    p.add_argument("--stop-on-violation", action="store_true",
                   help="end the run at the first violation the live verdict sees, with that "
                        "verdict (as the scenario's live.stop: violation does; default: run on "
                        "to the timeout, so the summary covers the whole run)")
    p.add_argument("-v", "--verbose", action="store_true",
                   help="print every node's full counters at the end (default: a table of "
                        "the counters that are not zero; full counters when something went "
                        "wrong)")
    p.add_argument("--timeout", type=float, default=None, metavar="S",
                   help="end the run S wall seconds after every node is alive (the fleet's "
                        "epoch), instead of the scenario's limits (default: live.wall_timeout_s "
                        "wall seconds or live.horizon_s fleet seconds, whichever comes first, "
                        "else never); a fleet not up within 60 s ends INCONCLUSIVE")
    p.add_argument("--seed", type=int, default=None, help="fleet seed (default: the scenario's)")
    p.add_argument("--runs", type=int, default=1, metavar="N",
                   help="run the fleet N times with seeds S, S+1, ... (default: 1)")
    _launch_network_arguments(p)
    p.add_argument("--accept-recorded", action="store_true",
                   help="let the nodes take recorded input that `twinfleet play --into-fleet` "
                        "injects (signed as recorded; the result then says so); without it "
                        "they drop and count it (rejected_recorded)")
    p.add_argument("--insecure-listen", action="store_true",
                   help="allow --listen on a plain tcp/udp endpoint reachable from other "
                        "machines: the fleet's traffic then crosses the network unencrypted")
    p.add_argument("--record-run", default=None, metavar="FILE",
                   help="append a run record to FILE as JSON lines, flushed per line (scenario, "
                        "seed, versions, node exits and respawns, end reason, statistics, summary)")
    p.add_argument("--record-events", default=None, metavar="FILE",
                   help="write every event each node dispatches to FILE as JSON lines (handler, "
                        "kind, sender, seq, stamp, choices, state digest), for `twinfleet "
                        "validate FILE SCENARIO`; with --runs N, FILE.1 ... FILE.N")
    add_launch_ros2_arguments(p)
    p.set_defaults(func=cmd_launch)


def _launch_network_arguments(p: argparse.ArgumentParser) -> None:
    """Where a launch's router is and whose key signs its nodes."""
    p.add_argument("--connect", default=None, metavar="EP",
                   help="join the Zenoh router at EP (e.g. tcp/10.0.0.2:7447) instead of embedding one")
    p.add_argument("--listen", default=None, metavar="EP",
                   help="endpoint of the embedded router (default: tcp/127.0.0.1:<free port>); "
                        "an endpoint other machines can reach must be tls/ or quic/ (README "
                        "\"Trust model\")")
    p.add_argument("--credentials", default=None, metavar="FILE",
                   help="with --connect: join the fleet whose registry entry FILE is (copied "
                        "from the machine that launched it, owner-only): its key signs this "
                        "launch's nodes (default: this machine's registry entry for EP)")


def _examples_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("examples", help="list the shipped example scenarios, or copy one to edit",
                       description="Without --copy: list the shipped scenarios (run one by name: "
                       "twinfleet launch c1a, twinfleet check c1a_rebeca). With --copy NAME: "
                       "copy that scenario and its map into DIR (default: here), the copy's "
                       "map path pointing at the copied map.")
    p.add_argument("--copy", default=None, metavar="NAME", help="the example to copy")
    p.add_argument("dir", nargs="?", default=None, metavar="DIR",
                   help="where --copy writes (default: the current directory)")
    p.set_defaults(func=cmd_examples)
