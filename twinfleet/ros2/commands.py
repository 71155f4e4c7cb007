"""The ROS 2 commands: `ros2 bridge` (registered here), `export --ros2` and `bag info BAG/`
(called by the runtime's commands), and the driver `launch --ros2` runs.

Each imports the ROS field's libraries when it runs; without the ``ros2`` extra it
says how to install them (exit 2).
"""

from __future__ import annotations

import argparse
import dataclasses
import signal
import sys
from collections.abc import Sequence
from importlib import resources
from pathlib import Path
from typing import Any

from twinfleet.runtime.access.connection import (
    CommandError,
    Connection,
    add_connection_arguments,
    connection,
)
from twinfleet.runtime.scenario.config import DEFAULT_ROS2_ROUTER, Ros2Config

INSTALL_HINT = "the ROS 2 bridge needs its libraries: pip install 'twinfleet[ros2]'"


def _need_libraries() -> None:
    try:
        import rosbags  # noqa: F401
    except ImportError:
        raise CommandError(INSTALL_HINT) from None


def export_rosbag2_command(args: argparse.Namespace) -> int:
    """`twinfleet export FILE --ros2 -o BAG/`."""
    _need_libraries()
    from twinfleet.ros2.mapping import MappingError
    from twinfleet.ros2.rosbag import ExportError, export_rosbag2

    try:
        written = export_rosbag2(args.file, args.output, mapping=args.mapping,
                                 near=(Path.cwd(),))
    except (ExportError, MappingError, OSError) as exc:
        raise CommandError(f"export --ros2: {exc}") from None
    topics = ", ".join(f"{t} ({n})" for (t, _), n in sorted(written.counts.items()))
    print(f"wrote {args.output}: rosbag2 (MCAP, CDR), {written.messages} messages on "
          f"{len(written.counts)} topics via {written.mapping}, stamped with fleet time: "
          f"{topics or 'none'}", flush=True)
    if written.left_out:
        print("left out (no ROS 2 form): " + ", ".join(
            f"{t} ({n})" for t, n in sorted(written.left_out.items())), file=sys.stderr)
    return 0


def rosbag2_info(path: str) -> int:
    """`twinfleet bag info BAG/` for a rosbag2 folder."""
    _need_libraries()
    from twinfleet.ros2.rosbag import is_rosbag2, print_bag_info

    if not is_rosbag2(path):
        raise CommandError(f"{path}: a folder but not a rosbag2 bag (no metadata.yaml)")
    try:
        print_bag_info(path, sys.stdout)
    except Exception as exc:  # rosbags raises its own errors for a damaged bag
        raise CommandError(f"{path}: {type(exc).__name__}: {exc}") from None
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add `twinfleet ros2 bridge`."""
    ros2 = sub.add_parser("ros2", help="the fleet on a ROS 2 network (rmw_zenoh): the bridge")
    actions = ros2.add_subparsers(dest="action", required=True, metavar="ACTION")
    text = ("bridge a running fleet to ROS 2: each fleet node appears as a ROS 2 node of its "
            "own name, its messages in standard ROS 2 types (docs/ros2.md), and routed ROS 2 "
            "topics enter the fleet as external input")
    p = actions.add_parser("bridge", help=text, description=text[0].upper() + text[1:] + ". "
                           "Runs until Ctrl-C; prints its counters then.")
    p.add_argument("--domain", type=int, default=0, metavar="N",
                   help="ROS 2 domain id (ROS_DOMAIN_ID; default: %(default)s)")
    p.add_argument("--router", default=DEFAULT_ROS2_ROUTER, metavar="EP",
                   help="Zenoh endpoint of the ROS 2 network's router, rmw_zenohd's "
                        "(default: %(default)s)")
    p.add_argument("--inbound", action="append", default=[], metavar="/ROS_TOPIC=/FLEET_TOPIC",
                   help="route a ROS 2 topic into a fleet topic, e.g. /goal_pose=/r1/goal "
                        "(RViz's 2D Goal Pose to robot r1; repeatable); only a fleet launched "
                        "with --ros2 takes it")
    p.add_argument("--mapping", default=None, metavar="MODULE:NAME",
                   help="the fleet's ROS 2 mapping (default: the one the fleet's scene names)")
    add_connection_arguments(p, fleet_help="the fleet to bridge (the scenario's name)")
    p.set_defaults(func=bridge_command)
    text = ("print the path of the shipped RViz2 config that shows a bridged robot fleet (map, "
            "TF, each robot's pose, scan and plan; 2D Goal Pose on /goal_pose)")
    rviz = actions.add_parser("rviz", help=text, description=text[0].upper() + text[1:] +
                              ': rviz2 -d "$(twinfleet ros2 rviz)".')
    rviz.set_defaults(func=rviz_command)


def rviz_config() -> Path:
    """The shipped RViz2 config file (package data)."""
    return Path(str(resources.files("twinfleet.ros2") / "rviz" / "fleet.rviz"))


def rviz_command(_args: argparse.Namespace) -> int:
    """`twinfleet ros2 rviz`."""
    print(rviz_config())
    return 0


def bridge_command(args: argparse.Namespace) -> int:
    """`twinfleet ros2 bridge --fleet NAME`."""
    _need_libraries()
    from twinfleet.ros2.bridge import parse_routes
    from twinfleet.ros2.live import BridgeError, BridgeSettings, FleetBridge
    from twinfleet.ros2.mapping import MappingError

    conn = connection(args)
    if conn.fleet == "*":
        raise CommandError("ros2 bridge needs --fleet NAME (or $TWINFLEET_FLEET)")
    try:
        routes = parse_routes(args.inbound)
        Ros2Config(domain=args.domain, router=args.router)
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    bridge = FleetBridge(BridgeSettings(conn.fleet, conn.endpoint, conn.auth, args.domain,
                                        args.router, routes, args.mapping, (Path.cwd(),)))

    import asyncio  # here: the other commands (check) never start a loop

    async def run() -> None:
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, bridge.stop.set)
        await bridge.run()

    try:
        asyncio.run(run())
    except (BridgeError, MappingError) as exc:
        raise CommandError(f"ros2 bridge: {exc}") from None
    return 0


def add_launch_ros2_arguments(p: argparse.ArgumentParser) -> None:
    """`launch`'s ROS 2 options: --ros2, --ros2-router, --ros2-mapping."""
    p.add_argument("--ros2", action="store_true",
                   help="run the ROS 2 bridge beside the fleet (docs/ros2.md; also when the "
                        "scenario has a ros2: section, whose domain, router and inbound topics "
                        "it uses): the nodes take the bridge's input on their external topics")
    p.add_argument("--ros2-router", default=None, metavar="EP",
                   help="with --ros2: the ROS 2 network's router (default: the ros2: section's, "
                        "else tcp/127.0.0.1:7447, rmw_zenohd's); a bridge that never reaches "
                        "it makes the run INCONCLUSIVE")
    p.add_argument("--ros2-mapping", default=None, metavar="MODULE:NAME",
                   help="with --ros2: the fleet's ROS 2 mapping, found as node classes are "
                        "(the scenario's folder, the working directory; default: the ros2: "
                        "section's, else the scene's, else none: every message by its fields)")


def launch_bridge(args: argparse.Namespace, scenario: Any) -> Any:
    """The ROS 2 bridge's driver for `launch` when asked for (``--ros2`` and its options, a
    ``ros2:`` section), else None; a named mapping is found as node classes are (the
    scenario's folder, the working directory)."""
    if not (args.ros2 or args.ros2_router or args.ros2_mapping or scenario.ros2 is not None):
        return None
    near = ([scenario.path.parent] if scenario.path is not None else []) + [Path.cwd()]
    return launch_driver(scenario.ros2, router=args.ros2_router, mapping=args.ros2_mapping,
                         near=near)


def launch_driver(config: Ros2Config | None, *, router: str | None = None,
                  mapping: str | None = None, near: Sequence[Path] = ()) -> Any:
    """The `run_fleet` driver of `launch --ros2`: the bridge with the scenario's ``ros2:``
    settings (default ones without), `router` and `mapping` overriding the section's. A
    named mapping is loaded here, before the fleet starts (its module searched in `near`
    too, as node classes are): one that does not load is a one-line error at once."""
    _need_libraries()
    from twinfleet.ros2 import live
    from twinfleet.ros2.mapping import MappingError, load_mapping

    config = config or Ros2Config()
    try:
        if router is not None:
            config = dataclasses.replace(config, router=router)
    except ValueError as exc:  # ConfigError: says which setting
        raise CommandError(f"--ros2-router: {exc}") from None
    name = mapping or config.mapping
    if name is not None:
        try:
            load_mapping(name, near)
        except MappingError as exc:
            raise CommandError(f"{'--ros2-mapping' if mapping else 'ros2.mapping'}: "
                               f"{exc}") from None
    routes: Sequence[tuple[str, str]] = config.inbound
    return live.launch_driver(dict(routes), domain=config.domain, router=config.router,
                              mapping=name, near=tuple(near))


def interface_export_command(args: argparse.Namespace) -> int:
    """`twinfleet interface export --ros2 DIR`: the types of the modules `args.module` names."""
    if not args.ros2:
        raise CommandError("interface export writes a ROS 2 package: give --ros2")
    _need_libraries()
    from twinfleet.ros2.interfaces import InterfaceError, write_package
    from twinfleet.ros2.live import fleet_interfaces
    from twinfleet.runtime.access.connection import import_modules

    import_modules(args.module)
    interfaces = fleet_interfaces()
    try:
        written = write_package(interfaces, args.package, args.dir)
    except (InterfaceError, OSError) as exc:
        raise CommandError(f"interface export: {exc}") from None
    for name, why in sorted(interfaces.skipped.items()):
        print(f"skipped {name}: {why}", file=sys.stderr)
    messages = [p.stem for p in written if p.suffix == ".msg"]
    print(f"wrote {written[0].parent.parent}: {len(messages)} messages "
          f"({', '.join(messages)}); build it in a ROS 2 workspace with colcon build", flush=True)
    for p in written:
        if p.suffix == ".msg":
            t = f"{args.package}/msg/{p.stem}"
            print(f"  {t}  {interfaces.types.type_hash(t)}")
    return 0


def print_ros_graph(conn: Connection, domain: int, what: str, *, types: bool = False,
                    verbose: bool = False, timeout_s: float = 1.0) -> None:
    """Print the ROS 2 nodes (`what` = "nodes") or topics of `domain` behind the connection's
    router (`node list` / `topic list` with ``--ros2-domain``)."""
    import zenoh

    from twinfleet.ros2.graph_list import graph_lines, ros_graph
    from twinfleet.runtime.access.connection import zenoh_conf

    with zenoh.open(zenoh_conf(conn.endpoint, conn.auth)) as session:
        graph = ros_graph(session, domain, timeout_s)
    for line in graph_lines(graph, what, types=types, verbose=verbose):
        print(line)
    sys.stdout.flush()


def ros_echo(conn: Connection, domain: int, topic: str, *, count: int | None = None,
             duration_s: float | None = None) -> int:
    """`twinfleet topic echo TOPIC --ros2-domain N`: each sample of a ROS 2 topic, its CDR
    decoded by the type its key names, one YAML document each, until `count` or
    `duration_s` (or Ctrl-C). A sample this process cannot decode is one line on stderr
    (the first of each reason) and counts toward `count`; the exit code is then 1
    (`EchoTally`)."""
    _need_libraries()
    import queue
    import time

    import yaml
    import zenoh

    from twinfleet.ros2.cdr import MessageError
    from twinfleet.ros2.live import fleet_interfaces
    from twinfleet.ros2.wire import WireError, ros_type_name
    from twinfleet.runtime.access.connection import zenoh_conf
    from twinfleet.runtime.tools.monitor.data_verbs import EchoTally

    types = fleet_interfaces().types  # standard types and the bridge's by-fields ones
    samples: queue.Queue[tuple[str, bytes]] = queue.Queue()
    expr = f"{domain}/{topic.strip('/')}/*/*"
    end = time.monotonic() + duration_s if duration_s is not None else None
    tally = EchoTally(topic, sys.stderr)
    with zenoh.open(zenoh_conf(conn.endpoint, conn.auth)) as session:
        session.declare_subscriber(expr, lambda s: samples.put((str(s.key_expr),
                                                                s.payload.to_bytes())))
        while (count is None or tally.seen < count) and (end is None or time.monotonic() < end):
            try:
                key, payload = samples.get(timeout=0.2)
            except queue.Empty:
                continue
            try:
                ros_type = ros_type_name(key.split("/")[-2])
                fields = types.decode(ros_type, payload)
            except (WireError, MessageError, IndexError) as exc:
                tally.undecodable(str(exc))
                continue
            print(yaml.safe_dump(_plain(fields), sort_keys=False) + "---", flush=True)
            tally.shown += 1
    return tally.exit_code()


def _plain(value: Any) -> Any:
    """A decoded message as YAML-safe values (bytes as lists of numbers)."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, bytes | bytearray):
        return list(value)
    if hasattr(value, "tolist"):  # a numpy array or scalar
        return value.tolist()
    return value
