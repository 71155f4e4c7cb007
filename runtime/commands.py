"""The live runtime's commands: launch, topic, service, node, view, examples (and record,
play, export).

    twinfleet launch SCENARIO [--time-scale K] [--timeout S] [--seed S] [--runs N]
                              [--connect EP] [--listen EP]
    twinfleet examples [--copy NAME [DIR]]
    twinfleet topic list|echo|hz|pub ...     twinfleet service list|call ...
    twinfleet node list
    twinfleet view [--connect EP] [--fleet F] [--port P] [--trace FILE]

SCENARIO is a scenario file or the name of a shipped example (`twinfleet examples`
lists them). `register(subparsers)` adds them to the `twinfleet` command line
(`twinfleet.cli`); `record`, `play` and `export` come from
`runtime.recording_commands`. Every command imports its engine when it runs.
"""

from __future__ import annotations

import argparse
import asyncio
import sys

from twinfleet.runtime import recording_commands
from twinfleet.runtime.cliargs import (
    add_connection_arguments,
    add_message_arguments,
    import_modules,
    need_fleet,
    zenoh_conf,
)


def register(sub: argparse._SubParsersAction) -> None:
    """Add the live runtime's subcommands to the `twinfleet` command line."""
    _launch_parser(sub)
    _topic_parser(sub)
    _service_parser(sub)
    _node_parser(sub)
    _view_parser(sub)
    _examples_parser(sub)
    recording_commands.register(sub)


def cmd_launch(args: argparse.Namespace) -> int:
    """`twinfleet launch`: validate, run the fleet `--runs` times, print summaries."""
    from twinfleet.runtime.scenario import ScenarioError, load_scenario

    try:
        scenario = load_scenario(args.scenario)
    except ScenarioError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    from twinfleet.runtime.launcher import format_result, run_fleet

    worst, passed = 0, 0
    for run in range(args.runs):
        seed = (args.seed if args.seed is not None else scenario.seed) + run
        if args.runs > 1:
            print(f"[launcher] run {run + 1}/{args.runs} (seed {seed})", flush=True)
        try:
            result = asyncio.run(run_fleet(scenario, time_scale=args.time_scale,
                                           timeout_s=args.timeout, seed=seed,
                                           connect=args.connect, listen=args.listen,
                                           run_record=args.record_run,
                                           record_events=_events_path(args, run)))
        except ValueError as exc:  # e.g. a bad TWINFLEET_ZENOH_CONFIG_OVERRIDE
            print(f"error: {exc}", file=sys.stderr)
            return 2
        for line in format_result(result):
            print(f"[launcher] {line}", flush=True)
        worst = max(worst, 0 if result.passed else 1)
        passed += result.passed
        if result.reason.startswith(("SIGINT", "SIGTERM")):
            break
    if args.runs > 1:
        print(f"[launcher] {scenario.name}: {passed}/{args.runs} passed, "
              f"{args.runs - passed}/{args.runs} failed", flush=True)
    return worst


def cmd_examples(args: argparse.Namespace) -> int:
    """`twinfleet examples`: list the shipped scenarios, or copy one (and its map) to edit."""
    from twinfleet.runtime.examples import ExampleError, copy_example, describe, shipped_scenarios

    if args.copy is None:
        if args.dir is not None:
            print("error: a directory is given only with --copy NAME", file=sys.stderr)
            return 2
        shipped = shipped_scenarios()
        width = max(map(len, shipped))
        for name, path in shipped.items():
            print(f"{name:<{width}}  {describe(path)}")
        print("\nrun one with `twinfleet launch NAME` or `twinfleet check NAME`; "
              "edit a copy: `twinfleet examples --copy NAME [DIR]`")
        return 0
    from twinfleet.runtime.scenario import ScenarioError, load_scenario

    try:
        files = copy_example(args.copy, args.dir or ".")
        load_scenario(files[0][0])  # the copy must load as it is
    except (ExampleError, ScenarioError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for path, written in files:
        print(f"{'wrote' if written else 'kept existing'} {path}")
    return 0


def _events_path(args: argparse.Namespace, run: int) -> str | None:
    """Where run `run` of `launch --record-events FILE` writes: FILE, or FILE.<k> with --runs."""
    if not args.record_events or args.runs == 1:
        return args.record_events
    return f"{args.record_events}.{run + 1}"


def cmd_topic(args: argparse.Namespace) -> int:
    """`twinfleet topic ...`."""
    from twinfleet.runtime import monitor

    out = sys.stdout
    if args.action == "list":
        return monitor.topic_list(zenoh_conf(args), args.fleet, out=out, verbose=args.verbose,
                                  timeout_s=args.query_timeout)
    if args.action == "echo":
        return monitor.topic_echo(zenoh_conf(args), args.fleet, args.topic, out=out,
                                  count=args.count, duration_s=args.duration)
    if args.action == "hz":
        return monitor.topic_hz(zenoh_conf(args), args.fleet, args.topic, out=out,
                                window=args.window, duration_s=args.duration)
    fleet = need_fleet(args)
    if fleet is None:
        return 2
    import_modules(args.module)
    return monitor.topic_pub(zenoh_conf(args), fleet, args.topic, args.type,
                             monitor.parse_data(args.data), out=out, rate_hz=args.rate,
                             count=None if args.count == 0 else args.count)


def cmd_service(args: argparse.Namespace) -> int:
    """`twinfleet service ...`."""
    from twinfleet.runtime import monitor

    if args.action == "list":
        return monitor.service_list(zenoh_conf(args), args.fleet, out=sys.stdout,
                                    verbose=args.verbose, timeout_s=args.query_timeout)
    fleet = need_fleet(args)
    if fleet is None:
        return 2
    import_modules(args.module)
    return monitor.service_call(zenoh_conf(args), fleet, args.service, args.type,
                                monitor.parse_data(args.data), out=sys.stdout,
                                timeout_s=args.timeout)


def cmd_node(args: argparse.Namespace) -> int:
    """`twinfleet node list`."""
    from twinfleet.runtime import monitor

    return monitor.node_list(zenoh_conf(args), args.fleet, out=sys.stdout, stats=args.stats,
                             timeout_s=args.query_timeout)


def cmd_view(args: argparse.Namespace) -> int:
    """`twinfleet view`: serve the live viewer (or a trace) on 127.0.0.1."""
    from twinfleet.runtime.viewer import run_viewer

    try:
        return run_viewer(connect=args.connect, fleet=args.fleet, port=args.port,
                          trace_path=args.trace)
    except (ValueError, KeyError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


def _launch_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("launch", help="run a scenario live: a router plus one process per node")
    p.add_argument("scenario", help="scenario YAML file, or the name of a shipped example "
                                    "(twinfleet examples lists them)")
    p.add_argument("--time-scale", type=float, default=None, metavar="K",
                   help="run fleet time K times faster than wall time (default: live.time_scale or 1)")
    p.add_argument("--timeout", type=float, default=None, metavar="S",
                   help="end the run after S wall seconds (default: live.timeout_s, else never)")
    p.add_argument("--seed", type=int, default=None, help="fleet seed (default: the scenario's)")
    p.add_argument("--runs", type=int, default=1, metavar="N",
                   help="run the fleet N times with seeds S, S+1, ... (default: 1)")
    p.add_argument("--connect", default=None, metavar="EP",
                   help="join the Zenoh router at EP (e.g. tcp/10.0.0.2:7447) instead of embedding one")
    p.add_argument("--listen", default=None, metavar="EP",
                   help="endpoint of the embedded router (default: tcp/127.0.0.1:<free port>)")
    p.add_argument("--record-run", default=None, metavar="FILE",
                   help="append a run record to FILE as JSON lines, flushed per line (scenario, "
                        "seed, versions, node exits and respawns, end reason, statistics, summary)")
    p.add_argument("--record-events", default=None, metavar="FILE",
                   help="write every event each node dispatches to FILE as JSON lines (handler, "
                        "kind, sender, seq, stamp, choices, state digest), for `twinfleet "
                        "validate FILE SCENARIO`; with --runs N, FILE.1 ... FILE.N")
    p.set_defaults(func=cmd_launch)


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


def _topic_parser(sub: argparse._SubParsersAction) -> None:
    topic = sub.add_parser("topic", help="list, echo, measure or publish topics")
    ts = topic.add_subparsers(dest="action", required=True, metavar="ACTION")
    tl = ts.add_parser("list", help="list topics with publishers or subscribers")
    tl.add_argument("-v", "--verbose", action="store_true", help="show which nodes publish/subscribe")
    te = ts.add_parser("echo", help="print messages on a topic")
    te.add_argument("topic", help="fully qualified topic name, e.g. /chatter")
    te.add_argument("--count", type=int, default=None, metavar="N", help="exit after N messages")
    te.add_argument("--duration", type=float, default=None, metavar="S", help="exit after S seconds")
    th = ts.add_parser("hz", help="print the rate of a topic every second")
    th.add_argument("topic", help="fully qualified topic name, e.g. /chatter")
    th.add_argument("--window", type=int, default=100, metavar="N",
                    help="number of recent messages the rate is computed over (default: 100)")
    th.add_argument("--duration", type=float, default=None, metavar="S", help="exit after S seconds")
    tp = ts.add_parser("pub", help="publish a message on a topic")
    tp.add_argument("topic", help="fully qualified topic name, e.g. /chatter")
    add_message_arguments(tp)
    tp.add_argument("--rate", type=float, default=1.0, metavar="HZ",
                    help="messages per second (default: 1)")
    tp.add_argument("--count", type=int, default=1, metavar="N",
                    help="number of messages, 0 for until Ctrl-C (default: 1)")
    for p in (tl, te, th, tp):
        add_connection_arguments(p)
        p.set_defaults(func=cmd_topic)


def _service_parser(sub: argparse._SubParsersAction) -> None:
    service = sub.add_parser("service", help="list or call services")
    ss = service.add_subparsers(dest="action", required=True, metavar="ACTION")
    sl = ss.add_parser("list", help="list served services")
    sl.add_argument("-v", "--verbose", action="store_true", help="show which nodes serve them")
    sc = ss.add_parser("call", help="call a service once and print the reply")
    sc.add_argument("service", help="fully qualified service name, e.g. /add_two_ints")
    add_message_arguments(sc)
    sc.add_argument("--timeout", type=float, default=2.0, metavar="S",
                    help="seconds to wait for the reply (default: 2)")
    for p in (sl, sc):
        add_connection_arguments(p)
        p.set_defaults(func=cmd_service)


def _node_parser(sub: argparse._SubParsersAction) -> None:
    node = sub.add_parser("node", help="inspect running nodes")
    node_sub = node.add_subparsers(dest="action", required=True, metavar="ACTION")
    nl = node_sub.add_parser("list", help="list running nodes (from liveliness tokens)")
    nl.add_argument("--stats", action="store_true", help="also show each node's counters")
    add_connection_arguments(nl)
    nl.set_defaults(func=cmd_node)


def _view_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("view", help="web page on 127.0.0.1 showing a live fleet, or stepping "
                                    "through a checker trace")
    p.add_argument("--port", type=int, default=8765, metavar="P",
                   help="TCP port of the page on 127.0.0.1; 0 picks a free one (default: %(default)s)")
    p.add_argument("--trace", default=None, metavar="FILE",
                   help="step through this checker trace JSON (from `twinfleet check --trace-out`) "
                        "instead of watching a live fleet")
    add_connection_arguments(p, fleet_help="fleet to show; '*' shows the first fleet whose data "
                             "arrives", discovery=False)
    p.set_defaults(func=cmd_view)
