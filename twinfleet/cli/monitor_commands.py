"""The ROS 2-style monitors of a running fleet: node, topic, service, param, interface.

    twinfleet node list|info     twinfleet topic list|info|type|echo|hz|pub
    twinfleet service list|type|call   twinfleet param list|get|set   twinfleet interface list|show

Monitors find the fleet in the fleet registry unless --connect is given
(`runtime.access.connection.connection`); each command imports its engine when it runs.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from twinfleet.runtime.access.connection import (
    CommandError,
    add_connection_arguments,
    add_message_arguments,
    add_wait_arguments,
    connection,
    import_modules,
    need_fleet,
)

ROS2_DOMAIN = ("--ros2-domain",)
ROS2_DOMAIN_OPTIONS: dict[str, Any] = {
    "type": int, "default": None, "metavar": "N",
    "help": "also list the ROS 2 (rmw_zenoh) nodes or topics of domain N behind the same "
            "router, marked (ros2); e.g. --connect tcp/127.0.0.1:7447 for rmw_zenohd's "
            "(needs twinfleet[ros2])"}


def register(sub: argparse._SubParsersAction) -> None:
    """Add the monitors' subcommands to the `twinfleet` command line."""
    _topic_parser(sub)
    _service_parser(sub)
    _node_parser(sub)
    _param_parser(sub)
    _interface_parser(sub)


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


MESSAGES = "twinfleet.nodes.msgs"  # what `interface export` writes without --module


def cmd_interface(args: argparse.Namespace) -> int:
    """`twinfleet interface list|show`: types of this process, and of the fleet when one runs;
    `interface export --ros2 DIR`: a ROS 2 package of them (`twinfleet.ros2.interfaces`)."""
    from twinfleet.runtime.tools.monitor import graph_verbs

    if args.action == "export":
        from twinfleet.ros2.commands import interface_export_command

        args.module = args.module or [MESSAGES]
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
