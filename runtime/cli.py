"""The `twinfleet` command line: a thin argparse layer over the launcher and monitors.

    twinfleet launch SCENARIO [--time-scale K] [--timeout S] [--seed S] [--runs N]
                              [--connect EP] [--listen EP]
    twinfleet topic list|echo|hz|pub ...     twinfleet service list|call ...
    twinfleet node list
    twinfleet view [--connect EP] [--fleet F] [--port P] [--trace FILE]
    twinfleet record SCENARIO|--connect EP -o run.mcap [--duration S]
    twinfleet play run.mcap [--rate K] [--connect EP]
    twinfleet export run.mcap -o run.json.mcap   (JSON copy for Foxglove)
    twinfleet launch SCENARIO --record-events FILE; twinfleet validate FILE SCENARIO
    twinfleet replay TRACE --live

Connection options are defined once (`add_connection_arguments`); `--connect`
defaults to $TWINFLEET_CONNECT and `--fleet` to $TWINFLEET_FLEET. `check` and
`replay` come from `checker.commands.register` when the checker is installed;
`record`, `play` and `export` from `runtime.recording_cli`.
"""

from __future__ import annotations

import argparse
import asyncio
import functools
import os
import sys
from collections.abc import Callable, Sequence

DEFAULT_CONNECT = "tcp/127.0.0.1:7447"


def add_connection_arguments(parser: argparse.ArgumentParser, *,
                             fleet_help: str = "fleet name (the scenario's name); '*' means every fleet",
                             discovery: bool = True) -> None:
    """Add --connect and --fleet (and, with `discovery`, --query-timeout) to a command."""
    group = parser.add_argument_group("connection")
    group.add_argument("--connect", metavar="EP", default=os.environ.get("TWINFLEET_CONNECT", DEFAULT_CONNECT),
                       help="Zenoh endpoint of the fleet's router, as printed by `twinfleet launch` "
                            "(default: $TWINFLEET_CONNECT or %(default)s)")
    group.add_argument("--fleet", default=os.environ.get("TWINFLEET_FLEET", "*"),
                       help=fleet_help + " (default: $TWINFLEET_FLEET or %(default)s)")
    if discovery:
        group.add_argument("--query-timeout", type=float, default=1.0, metavar="S",
                           help="seconds to wait for discovery answers (default: %(default)s)")


def _conf(args: argparse.Namespace):  # noqa: ANN202 - zenoh imported lazily
    from runtime.zenoh_transport import zenoh_config

    return zenoh_config(connect=[args.connect], mode="client")


def _need_fleet(args: argparse.Namespace) -> str | None:
    if args.fleet == "*":
        print(f"error: {args.command} {args.action} needs --fleet NAME (or $TWINFLEET_FLEET)",
              file=sys.stderr)
        return None
    return args.fleet


def cmd_launch(args: argparse.Namespace) -> int:
    """`twinfleet launch`: validate, run the fleet `--runs` times, print summaries."""
    from runtime.scenario import ScenarioError, load_scenario

    try:
        scenario = load_scenario(args.scenario)
    except ScenarioError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    from runtime.launcher import format_result, run_fleet

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


def _events_path(args: argparse.Namespace, run: int) -> str | None:
    """Where run `run` of `launch --record-events FILE` writes: FILE, or FILE.<k> with --runs."""
    if not args.record_events or args.runs == 1:
        return args.record_events
    return f"{args.record_events}.{run + 1}"


def cmd_render(args: argparse.Namespace) -> int:
    """`twinfleet render`: draw a scenario's start or a checker trace to PNG/GIF."""
    from runtime.scenario import ScenarioError, load_scenario

    source = args.source
    try:
        if source.endswith(".json"):
            from checker.trace import TraceError, load_trace

            try:
                trace = load_trace(source)
            except TraceError as exc:
                raise ValueError(str(exc)) from None
            scenario = load_scenario(trace["scenario"], {"profile": trace.get("profile") or "fixed"})
        else:
            trace, scenario = None, load_scenario(source)
        from nodes.render import save_pictures, scenario_view, trace_views

        views = (trace_views(scenario, trace, scan_of=args.scan_of, every_step=args.every_step)
                 if trace else [scenario_view(scenario, scan_of=args.scan_of)])
        frames = save_pictures(views, args.output, cell_px=args.cell_px)
    except (ScenarioError, ValueError, KeyError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except (TypeError, AttributeError) as exc:  # well-formed trace, states of another system
        print(f"error: {source}: the trace does not fit its scenario's nodes ({exc})", file=sys.stderr)
        return 2
    print(f"wrote {args.output} ({frames} frame{'s' if frames > 1 else ''})")
    return 0


def cmd_topic(args: argparse.Namespace) -> int:
    """`twinfleet topic ...`."""
    from runtime import monitor

    out = sys.stdout
    if args.action == "list":
        return monitor.topic_list(_conf(args), args.fleet, out=out, verbose=args.verbose,
                                  timeout_s=args.query_timeout)
    if args.action == "echo":
        return monitor.topic_echo(_conf(args), args.fleet, args.topic, out=out,
                                  count=args.count, duration_s=args.duration)
    if args.action == "hz":
        return monitor.topic_hz(_conf(args), args.fleet, args.topic, out=out,
                                window=args.window, duration_s=args.duration)
    fleet = _need_fleet(args)
    if fleet is None:
        return 2
    import_modules(args.module)
    return monitor.topic_pub(_conf(args), fleet, args.topic, args.type,
                             monitor.parse_data(args.data), out=out, rate_hz=args.rate,
                             count=None if args.count == 0 else args.count)


def cmd_service(args: argparse.Namespace) -> int:
    """`twinfleet service ...`."""
    from runtime import monitor

    if args.action == "list":
        return monitor.service_list(_conf(args), args.fleet, out=sys.stdout,
                                    verbose=args.verbose, timeout_s=args.query_timeout)
    fleet = _need_fleet(args)
    if fleet is None:
        return 2
    import_modules(args.module)
    return monitor.service_call(_conf(args), fleet, args.service, args.type,
                                monitor.parse_data(args.data), out=sys.stdout,
                                timeout_s=args.timeout)


def cmd_node(args: argparse.Namespace) -> int:
    """`twinfleet node list`."""
    from runtime import monitor

    return monitor.node_list(_conf(args), args.fleet, out=sys.stdout, stats=args.stats,
                             timeout_s=args.query_timeout)


def cmd_view(args: argparse.Namespace) -> int:
    """`twinfleet view`: serve the live viewer (or a trace) on 127.0.0.1."""
    from runtime.viewer import run_viewer

    try:
        return run_viewer(connect=args.connect, fleet=args.fleet, port=args.port,
                          trace_path=args.trace)
    except (ValueError, KeyError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


def import_modules(modules: Sequence[str]) -> None:
    import importlib

    for name in modules:
        importlib.import_module(name)


def _add_message_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("type", help="message type name, e.g. std_msgs/String")
    p.add_argument("data", nargs="?", default="",
                   help="message fields as YAML, e.g. \"{data: hello}\" (default: no fields)")
    p.add_argument("--module", action="append", default=[], metavar="MODULE",
                   help="import MODULE first so its message types are validated (repeatable)")


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser."""
    parser = argparse.ArgumentParser(prog="twinfleet", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _launch_parser(sub)
    _render_parser(sub)
    _topic_parser(sub)
    _service_parser(sub)
    _view_parser(sub)
    from runtime.recording_cli import register as register_recording

    register_recording(sub)
    node = sub.add_parser("node", help="inspect running nodes")
    node_sub = node.add_subparsers(dest="action", required=True, metavar="ACTION")
    nl = node_sub.add_parser("list", help="list running nodes (from liveliness tokens)")
    nl.add_argument("--stats", action="store_true", help="also show each node's counters")
    add_connection_arguments(nl)
    nl.set_defaults(func=cmd_node)
    try:
        from checker.commands import register  # type: ignore[import-not-found]
    except ImportError:
        pass
    else:
        register(sub)
        _add_live_replay(sub)
    _validate_parser(sub)
    from agreement.commands import register as register_experiment

    register_experiment(sub)
    return parser


def _add_live_replay(sub: argparse._SubParsersAction) -> None:
    """`replay TRACE --live`: the checker's replay command, plus a live re-enactment."""
    replay = sub.choices.get("replay")
    if replay is None:
        return
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
    replay.set_defaults(func=functools.partial(_replay_or_live, replay.get_default("func")))


def _replay_or_live(original: Callable[[argparse.Namespace], int],
                    args: argparse.Namespace) -> int:
    if not args.live:
        return original(args)
    from agreement.live_replay import live_replay_command

    return live_replay_command(args)


def cmd_validate(args: argparse.Namespace) -> int:
    """`twinfleet validate`: is a recorded live run a path of the checker's transitions?"""
    from agreement.validate import validate_command

    return validate_command(args)


def _validate_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("validate", help="check that a live run recorded with `launch "
                                        "--record-events` is a path of the checker's transitions",
                       description="Find an interleaving of the nodes' logged events that the "
                       "checker's transition relation can run, with the same arguments, "
                       "ctx.choose answers and node states; report the first step it cannot "
                       "explain (exit 0 valid, 1 unexplained, 2 bad input).")
    p.add_argument("events", help="event log written by `twinfleet launch --record-events FILE`")
    p.add_argument("scenario", help="the scenario YAML the run used")
    p.add_argument("--tolerance-ms", type=int, default=None, metavar="T",
                   help="also judge timing: events whose model times differ by at most T ms may "
                        "run in either order; 0 = the checker's exact rules (default: judge "
                        "order and state only, and report the first step outside the exact "
                        "timing rules and the tolerance this run needs)")
    p.add_argument("--window-ms", type=int, default=5, metavar="W",
                   help="live events of different nodes dispatched within W ms of each other "
                        "may be taken in either order (default: %(default)s)")
    p.add_argument("--semantics", choices=("ros", "rebeca"), default=None,
                   help="checker message rules (default: the scenario's)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.set_defaults(func=cmd_validate)


def _launch_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("launch", help="run a scenario live: a router plus one process per node")
    p.add_argument("scenario", help="scenario YAML file (see launch/)")
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


def _render_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("render", help="draw a scenario (start, goals, first plans) or a checker trace")
    p.add_argument("source", help="scenario YAML, or a trace JSON written by `twinfleet check`")
    p.add_argument("-o", "--output", required=True, metavar="FILE",
                   help="FILE.png: one picture (a trace's last step, with the collision circled); "
                        "FILE.gif: one frame per step in which a robot moved")
    p.add_argument("--scan-of", metavar="ROBOT", default=None,
                   help="draw the scan rays of this robot (e.g. r1)")
    p.add_argument("--every-step", action="store_true",
                   help="for a GIF of a trace, one frame per step even when nothing moved")
    p.add_argument("--cell-px", type=int, default=12, metavar="N",
                   help="pixels per grid cell (default: %(default)s)")
    p.set_defaults(func=cmd_render)


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
    _add_message_arguments(tp)
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
    _add_message_arguments(sc)
    sc.add_argument("--timeout", type=float, default=2.0, metavar="S",
                    help="seconds to wait for the reply (default: 2)")
    for p in (sl, sc):
        add_connection_arguments(p)
        p.set_defaults(func=cmd_service)


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


def main(argv: Sequence[str] | None = None) -> int:
    """Console script `twinfleet`."""
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
