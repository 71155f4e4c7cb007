"""The live runtime's commands: launch, examples, the ROS 2-style monitors, view, foxglove
(and record, play, export, bag).

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
import asyncio
import sys
from typing import Any

from twinfleet.cli import recording_commands, viewer_commands
from twinfleet.ros2.commands import add_launch_ros2_arguments, launch_bridge
from twinfleet.runtime.access.connection import (
    CommandError,
    add_connection_arguments,
    add_message_arguments,
    add_wait_arguments,
    connection,
    error_prefix,
    import_modules,
    need_fleet,
)
from twinfleet.runtime.scenario.overrides import add_override_arguments, override_words


def register(sub: argparse._SubParsersAction) -> None:
    """Add the live runtime's subcommands to the `twinfleet` command line."""
    _launch_parser(sub)
    _topic_parser(sub)
    _service_parser(sub)
    _node_parser(sub)
    _param_parser(sub)
    _interface_parser(sub)
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
    from twinfleet.runtime.fleet.launcher import FleetConflict, format_result, run_fleet
    bridge = launch_bridge(args, scenario)

    worst, codes = 0, []
    for run in range(args.runs):
        seed = (args.seed if args.seed is not None else scenario.seed) + run
        if args.runs > 1:
            print(f"[launcher] run {run + 1}/{args.runs} (seed {seed})", flush=True)
        try:
            result = asyncio.run(run_fleet(scenario, time_scale=args.time_scale,
                                           timeout_s=args.timeout, seed=seed,
                                           connect=args.connect, listen=args.listen,
                                           run_record=args.record_run,
                                           record_events=_events_path(args, run),
                                           params=params, auth=auth,
                                           bridge=bridge is not None, driver=bridge,
                                           accept_recorded=args.accept_recorded,
                                           node_args=["--verbose"] if args.verbose else [],
                                           until_settled=args.until_settled or None,
                                           until_violation=args.stop_on_violation or None))
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
    from twinfleet.runtime.scenario.examples import (
        ExampleError,
        copy_example,
        describe,
        shipped_scenarios,
    )

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


def cmd_topic(args: argparse.Namespace) -> int:
    """`twinfleet topic ...`."""
    from twinfleet.runtime.tools.monitor import data_verbs, graph_verbs

    conn, out, wait = connection(args), sys.stdout, args.query_timeout
    if args.action == "list":
        code = graph_verbs.topic_list(conn, out=out, verbose=args.verbose, types=args.show_types,
                                      timeout_s=wait)
        _ros2_graph(args, conn, "topics", types=args.show_types, verbose=args.verbose)
        return code
    if args.action == "info":
        return graph_verbs.topic_info(conn, args.topic, out=out, verbose=args.verbose, timeout_s=wait)
    if args.action == "type":
        return graph_verbs.topic_type(conn, args.topic, out=out, timeout_s=wait)
    if args.action == "echo" and args.ros2_domain is not None:
        from twinfleet.ros2.commands import ros_echo

        return ros_echo(conn, args.ros2_domain, args.topic, count=1 if args.once else args.count,
                        duration_s=args.duration)
    if args.action == "echo":
        count = 1 if args.once else args.count
        return data_verbs.topic_echo(conn, args.topic, out=out, count=count,
                                       duration_s=args.duration, field=args.field,
                                       wait=args.wait, timeout_s=wait, full=args.full)
    if args.action == "hz":
        return data_verbs.topic_hz(conn, args.topic, out=out, window=args.window,
                                     duration_s=args.duration, timeout_s=wait, wait=args.wait)
    import_modules(args.module)
    need_fleet(args, conn)
    data_verbs.refuse_other_type(conn, args.topic, args.type, force=args.force, timeout_s=wait)
    count = 1 if args.once else args.times
    fields = ros_typed(args.type, parse_fields(args.data))
    return data_verbs.topic_pub(conn, args.topic, args.type, fields, out=out,
                                  rate_hz=args.rate, count=None if count == 0 else count,
                                  timeout_s=wait)


def parse_fields(text: str) -> dict:
    """The DATA argument of `topic pub` / `service call` as a mapping (one-line errors)."""
    from twinfleet.runtime.tools.monitor.payload import PayloadError, parse_data

    try:
        return parse_data(text)
    except PayloadError as exc:
        raise CommandError(str(exc)) from None


def ros_typed(type_name: str, fields: dict, *, service: bool = False) -> dict:
    """`fields` as a standard ROS 2 type holds them, as ROS 2 users type them
    (``{linear: {x: 1.0}}``: nested maps, the rest defaults; `twinfleet.interfaces.plain`);
    the fields of any other type unchanged."""
    from twinfleet.interfaces import FieldValueError, InterfaceError
    from twinfleet.interfaces.plain import ros_typed as complete

    try:
        typed = complete(type_name, fields, service=service)
    except (FieldValueError, InterfaceError) as exc:
        raise CommandError(str(exc)) from None
    return fields if typed is None else typed


def cmd_service(args: argparse.Namespace) -> int:
    """`twinfleet service ...`."""
    from twinfleet.runtime.tools.monitor import data_verbs, graph_verbs

    conn = connection(args)
    if args.action == "list":
        return graph_verbs.service_list(conn, out=sys.stdout, verbose=args.verbose,
                                    types=args.show_types, timeout_s=args.query_timeout)
    if args.action == "type":
        return graph_verbs.service_type(conn, args.service, out=sys.stdout,
                                    timeout_s=args.query_timeout)
    import_modules(args.module)
    need_fleet(args, conn)
    data_verbs.refuse_other_type(conn, args.service, args.type, service=True, force=args.force,
                                 timeout_s=args.query_timeout)
    fields = ros_typed(args.type, parse_fields(args.data), service=True)
    return data_verbs.service_call(conn, args.service, args.type, fields,
                                     out=sys.stdout, timeout_s=args.timeout,
                                     discovery_s=args.query_timeout, full=args.full)


def cmd_node(args: argparse.Namespace) -> int:
    """`twinfleet node list|info`."""
    from twinfleet.runtime.tools.monitor import graph_verbs

    conn = connection(args)
    if args.action == "info":
        return graph_verbs.node_info(conn, args.node, out=sys.stdout, timeout_s=args.query_timeout)
    code = graph_verbs.node_list(conn, out=sys.stdout, stats=args.stats,
                                 timeout_s=args.query_timeout)
    _ros2_graph(args, conn, "nodes")
    return code


def _ros2_graph(args: argparse.Namespace, conn: Any, what: str, **shown: bool) -> None:
    """With ``--ros2-domain N``: the ROS 2 nodes or topics on the same Zenoh network too."""
    if args.ros2_domain is not None:
        from twinfleet.ros2.commands import print_ros_graph

        print_ros_graph(conn, args.ros2_domain, what, timeout_s=args.query_timeout, **shown)


def cmd_param(args: argparse.Namespace) -> int:
    """`twinfleet param list|get|dump|set`."""
    from twinfleet.runtime.tools.monitor import graph_verbs

    conn = connection(args)
    if args.action == "set":
        return _param_set(args, conn)
    if args.action == "get":
        return graph_verbs.param_get(conn, args.node, args.name, out=sys.stdout,
                                 timeout_s=args.query_timeout)
    if args.action == "dump":
        return graph_verbs.param_dump(conn, args.node, out=sys.stdout,
                                      timeout_s=args.query_timeout)
    return graph_verbs.param_list(conn, args.node, out=sys.stdout, timeout_s=args.query_timeout)


def _param_set(args: argparse.Namespace, conn: Any) -> int:
    """`param set`: an rclpy node's own service sets it live (docs/rclpy.md); a native node's
    parameters are fixed for a launch."""
    from twinfleet.rclpy.param_service import SetParameter
    from twinfleet.runtime.contract.messages import type_name_of
    from twinfleet.runtime.tools.monitor import data_verbs

    node = args.node.strip("/")
    try:
        return data_verbs.service_call(
            conn, f"/{node}/set_parameter", type_name_of(SetParameter),
            {"name": args.name, "value": args.value}, out=sys.stdout,
            timeout_s=args.query_timeout, discovery_s=args.query_timeout)
    except CommandError as exc:
        if "no server" not in str(exc):
            raise
    raise CommandError(f"node {node!r} is not an rclpy node: its parameters are fixed for a "
                       f"launch (the checker checks the values a run starts with); set them "
                       f"when launching: twinfleet launch SCENARIO {node}.{args.name}:={args.value}")


def cmd_interface(args: argparse.Namespace) -> int:
    """`twinfleet interface list|show`: types of this process, and of the fleet when one runs;
    `interface export --ros2 DIR`: a ROS 2 package of them (`twinfleet.ros2.interfaces`)."""
    from twinfleet.runtime.tools.monitor import graph_verbs

    if args.action == "export":
        from twinfleet.ros2.commands import interface_export_command

        return interface_export_command(args)
    if args.action == "show":
        from twinfleet.interfaces.show import definition_text

        text = definition_text(args.type)  # a standard ROS 2 type: its definition decides
        if text is not None:
            print(text, end="", flush=True)
            return 0
    import_modules(args.module)
    try:
        conn = connection(args)
    except CommandError:
        if args.connect or args.fleet != "*":
            raise
        conn = None  # no fleet running: the types this process knows still answer
    if args.action == "show":
        return graph_verbs.interface_show(conn, args.type, out=sys.stdout,
                                      timeout_s=args.query_timeout)
    return graph_verbs.interface_list(conn, out=sys.stdout, timeout_s=args.query_timeout)


def _launch_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("launch", help="run a scenario live: a router plus one process per node",
                       description="Run a scenario live: an embedded Zenoh router plus one process "
                       "per node. The scenario's properties are judged on the running fleet "
                       "(runtime verification over the states the nodes report); the run ends "
                       "with `result: PASSED` (exit 0), `FAILED` and the property violated (1), "
                       "`INCONCLUSIVE` and why (3: a node dropped samples or stalled), "
                       "`CONTRACT BREACH` (4: a node published a type its topic does not carry), "
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


ROS2_DOMAIN = ("--ros2-domain",)
ROS2_DOMAIN_OPTIONS: dict[str, Any] = {
    "type": int, "default": None, "metavar": "N",
    "help": "also list the ROS 2 (rmw_zenoh) nodes or topics of domain N behind the same "
            "router, marked (ros2); e.g. --connect tcp/127.0.0.1:7447 for rmw_zenohd's "
            "(needs twinfleet[ros2])"}


def _sub(parent: argparse._SubParsersAction, name: str, text: str) -> argparse.ArgumentParser:
    return parent.add_parser(name, help=text, description=text[0].upper() + text[1:] + ".")


def _topic_parser(sub: argparse._SubParsersAction) -> None:
    topic = sub.add_parser("topic", help="list, inspect, echo, measure or publish topics")
    ts = topic.add_subparsers(dest="action", required=True, metavar="ACTION")
    tl = _sub(ts, "list", "list topics with publishers or subscribers")
    tl.add_argument("-t", "--show-types", action="store_true",
                    help="also show each topic's message type (learned from its messages)")
    tl.add_argument("-v", "--verbose", action="store_true", help="show which nodes publish/subscribe")
    tl.add_argument(*ROS2_DOMAIN, **ROS2_DOMAIN_OPTIONS)
    ti = _sub(ts, "info", "print a topic's type and its publisher and subscription counts")
    ti.add_argument("topic", help="fully qualified topic name, e.g. /poses")
    ti.add_argument("-v", "--verbose", action="store_true",
                    help="also list each publisher and subscriber with its node and QoS")
    tt = _sub(ts, "type", "print a topic's message type")
    tt.add_argument("topic", help="fully qualified topic name, e.g. /poses")
    te = _sub(ts, "echo", "print messages on a topic (a latched topic's last one at once)")
    te.add_argument("topic", help="fully qualified topic name, e.g. /chatter")
    te.add_argument("--once", action="store_true", help="print one message and exit")
    te.add_argument("--count", type=int, default=None, metavar="N", help="exit after N messages")
    te.add_argument("--field", default=None, metavar="PATH",
                    help="print only this field of the message, bare, dotted for nesting "
                         "(e.g. data, cell, cell.0); with --full, of the envelope")
    te.add_argument("--full", action="store_true",
                    help="print the whole envelope (type, stamp_ms, seq, sender, data) instead "
                         "of the message's fields")
    te.add_argument("--duration", type=float, default=None, metavar="S", help="exit after S seconds")
    add_wait_arguments(te, "for a publisher of a topic no node uses yet")
    te.add_argument("--ros2-domain", type=int, default=None, metavar="N",
                    help="echo a ROS 2 (rmw_zenoh) topic of domain N behind the same router "
                         "instead, decoding its CDR (standard types and the bridge's own; "
                         "--field and --wait do not apply; needs twinfleet[ros2])")
    th = _sub(ts, "hz", "print the rate of a topic every second")
    th.add_argument("topic", help="fully qualified topic name, e.g. /chatter")
    th.add_argument("--window", type=int, default=100, metavar="N",
                    help="number of recent messages the rate is computed over (default: 100)")
    th.add_argument("--duration", type=float, default=None, metavar="S", help="exit after S seconds")
    add_wait_arguments(th, "for a publisher of a topic no node uses yet")
    tp = _sub(ts, "pub", "publish a message on a topic (checked against its type first)")
    tp.add_argument("topic", help="fully qualified topic name, e.g. /chatter")
    add_message_arguments(tp)
    tp.add_argument("-r", "--rate", type=float, default=1.0, metavar="HZ",
                    help="messages per second (default: 1)")
    tp.add_argument("-t", "--times", "--count", dest="times", type=int, default=1, metavar="N",
                    help="number of messages, 0 for until Ctrl-C (default: 1; ros2's default "
                         "is until Ctrl-C: say -t 0)")
    tp.add_argument("-1", "--once", action="store_true", help="publish one message and exit")
    for p in (tl, ti, tt, te, th, tp):
        add_connection_arguments(p, discovery=True)
        p.set_defaults(func=cmd_topic)


def _service_parser(sub: argparse._SubParsersAction) -> None:
    service = sub.add_parser("service", help="list, inspect or call services")
    ss = service.add_subparsers(dest="action", required=True, metavar="ACTION")
    sl = _sub(ss, "list", "list served services")
    sl.add_argument("-t", "--show-types", action="store_true",
                    help="also show each service's request and reply types (from the serving "
                         "handler's annotations; ? where it has none)")
    sl.add_argument("-v", "--verbose", action="store_true", help="show which nodes serve them")
    st = _sub(ss, "type", "print a service's request and reply types as REQUEST -> REPLY")
    st.add_argument("service", help="fully qualified service name, e.g. /generate_path")
    sc = _sub(ss, "call", "call a service once and print the reply")
    sc.add_argument("service", help="fully qualified service name, e.g. /add_two_ints")
    add_message_arguments(sc)
    sc.add_argument("--timeout", type=float, default=2.0, metavar="S",
                    help="seconds to wait for the reply (default: 2)")
    sc.add_argument("--full", action="store_true",
                    help="print the reply's whole envelope instead of its fields")
    for p in (sl, st, sc):
        add_connection_arguments(p, discovery=True)
        p.set_defaults(func=cmd_service)


def _verbs(sub: argparse._SubParsersAction, name: str, text: str, func: Any,
           verbs: dict[str, tuple[str, list[tuple[str, dict[str, Any]]]]]
           ) -> dict[str, argparse.ArgumentParser]:
    """A command with sub-verbs, each with its positional arguments and the connection options."""
    parent = sub.add_parser(name, help=text)
    actions = parent.add_subparsers(dest="action", required=True, metavar="ACTION")
    made = {}
    for verb, (verb_text, arguments) in verbs.items():
        p = made[verb] = _sub(actions, verb, verb_text)
        for arg, options in arguments:
            p.add_argument(arg, **options)
        add_connection_arguments(p, discovery=True)
        p.set_defaults(func=func)
    return made


def _node_parser(sub: argparse._SubParsersAction) -> None:
    made = _verbs(sub, "node", "list and inspect running nodes", cmd_node, {
        "list": ("list running nodes (from liveliness tokens)", []),
        "info": ("show a node's topics with types, services, timers, parameters",
                 [("node", {"help": "node name, e.g. r1 or /r1"})])})
    made["list"].add_argument("--stats", action="store_true",
                              help="also show each node's counters")
    made["list"].add_argument(*ROS2_DOMAIN, **ROS2_DOMAIN_OPTIONS)


def _param_parser(sub: argparse._SubParsersAction) -> None:
    _verbs(sub, "param", "list, read and dump node parameters", cmd_param, {
        "list": ("list the parameters of every node, or of one",
                 [("node", {"nargs": "?", "default": None,
                            "help": "node name (default: every node)"})]),
        "get": ("print one parameter of a node",
                [("node", {"help": "node name, e.g. r1"}),
                 ("name", {"help": "parameter name, e.g. speed"})]),
        "dump": ("print a node's parameters in force as a ROS 2 parameter file (YAML)",
                 [("node", {"help": "node name, e.g. r1"})]),
        "set": ("set a parameter of a running rclpy node (its on-set callbacks may refuse); "
                "a native node's parameters are fixed per launch (says how to override them)",
                [("node", {"help": "node name, e.g. r1"}),
                 ("name", {"help": "parameter name, e.g. speed"}),
                 ("value", {"help": "the value, as YAML (3.0, true, auto, [1, 2])"})])})


def _interface_parser(sub: argparse._SubParsersAction) -> None:
    made = _verbs(sub, "interface", "list message types and show their fields", cmd_interface, {
        "list": ("list the message types known here and to the running fleet", []),
        "show": ("show the fields of a message type",
                 [("type", {"help": "type name, e.g. std_msgs/String or "
                                    "std_msgs/msg/String"})]),
        "export": ("write the message types as a colcon-buildable ROS 2 interface package "
                   "(--ros2), the types the ROS 2 bridge carries by their fields",
                   [("dir", {"help": "directory to write the package folder into"})])})
    for p in made.values():
        p.add_argument("--module", action="append", default=[], metavar="MODULE",
                       help="import MODULE first so its message types are known (repeatable; "
                            "export: default twinfleet.nodes.msgs)")
    made["export"].add_argument("--ros2", action="store_true",
                                help="a ROS 2 package (.msg files, package.xml, CMakeLists.txt; "
                                     "the only export there is; needs twinfleet[ros2])")
    made["export"].add_argument("--package", default="twinfleet_msgs",
                                help="the package (and type prefix) to export (default: "
                                     "%(default)s)")
