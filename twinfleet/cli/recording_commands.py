"""`twinfleet record`, `play`, `export` and `bag info`: fleet topics to MCAP files and back.

The engines live in `runtime.tools.record.recorder` (record, play), `runtime.tools.record.mcap_export`
(the JSON and Foxglove copies) and `runtime.tools.record.bag` (summaries); this module is
their argparse layer. Without --connect, `record` joins the fleet found in the
fleet registry, and `play` is its own router on a free port and registers the
recorded fleet there, so `twinfleet topic echo` finds it without options.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from twinfleet.runtime.access.connection import (
    CommandError,
    add_connection_arguments,
    add_wait_arguments,
    connection,
    error_prefix,
    import_modules,
)
from twinfleet.runtime.contract.environment import EnvVar, env_value


def cmd_record(args: argparse.Namespace) -> int:
    """`twinfleet record`: launch a scenario (or join a fleet) and write its topics to MCAP."""
    import asyncio  # here: the other commands (check) never start a loop

    import zenoh

    from twinfleet.runtime.fleet.launcher import format_result
    from twinfleet.runtime.scenario.spec import ScenarioError, load_scenario
    from twinfleet.runtime.tools.record import recorder

    import_modules(args.module)
    if args.scenario is not None and args.connect:
        print(f"{error_prefix(args)} give a SCENARIO to launch or --connect EP of a running fleet, not both "
              "(with a SCENARIO the recorder is the fleet's router: see --listen)", file=sys.stderr)
        return 2
    try:
        if args.scenario is None:
            conn = _joined(args)
            result, rec = None, asyncio.run(recorder.record_live(
                conn.endpoint, conn.fleet, args.output, duration_s=args.duration,
                handle_signals=True, auth=conn.auth if args.credentials else None))
        else:
            result, rec = asyncio.run(recorder.record_scenario(
                load_scenario(args.scenario), args.output, time_scale=args.time_scale,
                duration_s=args.duration, seed=args.seed, listen=args.listen))
    except (ScenarioError, OSError, zenoh.ZError) as exc:
        print(f"{error_prefix(args)} {exc}", file=sys.stderr)
        return 2
    for line in format_result(result) if result is not None else ():
        print(f"[launcher] {line}", flush=True)
    if rec.failed is not None:
        raise CommandError(rec.failed)
    print(f"wrote {args.output}: {rec.messages} messages on {rec.topics} topics", flush=True)
    return 0 if result is None else result.exit_code


def _joined(args: argparse.Namespace):  # noqa: ANN202 - a cliargs.Connection
    """The running fleet `record` joins: --connect, else the one in the fleet registry."""
    if not args.connect:
        args.connect = env_value(EnvVar.CONNECT)
    try:
        return connection(args)
    except CommandError as exc:
        raise CommandError(f"record needs a SCENARIO to launch, or a running fleet: {exc}") from None


def cmd_play(args: argparse.Namespace) -> int:
    """`twinfleet play`: re-publish a recording onto Zenoh (module docstring)."""
    import zenoh

    from twinfleet.runtime.access import registry
    from twinfleet.runtime.access.connection import zenoh_error_text
    from twinfleet.runtime.access.fleetauth import login_settings, registry_auth
    from twinfleet.runtime.fleet.launcher import free_port
    from twinfleet.runtime.host.zenoh_transport import zenoh_config
    from twinfleet.runtime.tools.record.bag import RecordingError, check_readable, read_summary
    from twinfleet.runtime.tools.record.recorder import play

    try:
        summary = read_summary(args.file)
        check_readable(args.file)
    except RecordingError as exc:
        raise CommandError(str(exc)) from None
    if args.into_fleet:
        return _play_into_fleet(args)
    listen = args.listen or (None if args.connect else f"tcp/127.0.0.1:{free_port()}")
    if listen:
        def make_config():  # noqa: ANN202 - zenoh imported lazily
            return zenoh_config(listen=[listen], mode="router")
    else:
        def make_config():  # noqa: ANN202 - zenoh imported lazily
            return zenoh_config(connect=[args.connect], mode="client",
                                settings=login_settings(registry_auth(args.connect), write=True))
    fleet = None if args.fleet == "*" else args.fleet
    name = fleet or summary.metadata.get("twinfleet", {}).get("fleet")
    entry = None
    if listen and name and name != "*":
        print(f"[play] fleet {name!r} on {listen}; monitor with: twinfleet topic list", flush=True)
        entry = registry.register(name, listen, scenario=str(args.file), kind="play")
    try:
        return play(make_config, args.file, rate=args.rate, fleet=fleet, wait_s=args.wait)
    except zenoh.ZError as exc:
        where = f"--listen {listen}" if listen else f"--connect {args.connect}"
        raise CommandError(f"play: cannot open {where}: {zenoh_error_text(exc)}") from None
    finally:
        registry.unregister(entry)


def _play_into_fleet(args: argparse.Namespace) -> int:
    """`play --into-fleet`: join the running fleet (--connect, --credentials or the registry)
    with its operator login, and sign every message as recorded input with its key."""
    import zenoh

    from twinfleet.runtime.access.connection import zenoh_conf, zenoh_error_text
    from twinfleet.runtime.tools.record.recorder import play

    if args.listen:
        raise CommandError("play --into-fleet joins a running fleet: give --connect EP (or "
                           "nothing: the fleet running here), not --listen")
    conn = connection(args)
    if conn.auth.key is None or conn.auth.operator is None:
        raise CommandError(f"play --into-fleet: no credentials for the fleet at {conn.endpoint} "
                           "(launched on another machine? pass --credentials FILE, a copy of "
                           "its registry entry)")
    fleet = None if conn.fleet == "*" else conn.fleet
    print(f"[play] into fleet {conn.fleet!r} at {conn.endpoint}, signed as recorded input "
          "(taken only by a fleet launched with --accept-recorded)", flush=True)
    try:
        return play(lambda: zenoh_conf(conn.endpoint, conn.auth, write=True), args.file,
                    rate=args.rate, fleet=fleet, wait_s=args.wait, key=conn.auth.key)
    except zenoh.ZError as exc:
        raise CommandError(f"play: cannot join {conn.endpoint}: {zenoh_error_text(exc)}") from None


def cmd_bag(args: argparse.Namespace) -> int:
    """`twinfleet bag info FILE` and `twinfleet bag repair FILE [-o OUT]`."""
    from twinfleet.runtime.tools.record.bag import RecordingError, print_info, read_summary, repair

    if args.action == "info" and Path(args.file).is_dir():
        from twinfleet.ros2.commands import rosbag2_info
        return rosbag2_info(args.file)
    try:
        if args.action == "repair":
            count, out = repair(args.file, getattr(args, "output", None))
            print(f"repaired {args.file}: {count} messages written to {out}", flush=True)
            return 0
        print_info(read_summary(args.file), sys.stdout)
    except RecordingError as exc:
        raise CommandError(str(exc)) from None
    except OSError as exc:
        raise CommandError(f"{args.file}: {exc.strerror or exc}") from None
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    """`twinfleet export`: a JSON-encoded copy of a recording."""
    from mcap.exceptions import McapError

    from twinfleet.runtime.tools.record.bag import RecordingError, check_readable
    from twinfleet.runtime.tools.record.mcap_export import export_json

    if args.ros2:
        from twinfleet.ros2.commands import export_rosbag2_command
        return export_rosbag2_command(args)
    try:
        check_readable(args.file)
        done = export_json(args.file, args.output)
    except (ValueError, OSError, McapError, RecordingError) as exc:
        print(f"{error_prefix(args)} {exc}", file=sys.stderr)
        return 2
    view = ("and their Foxglove view (/foxglove/map, /foxglove/robots, /foxglove/<robot>/scan, "
            "/foxglove/collisions)" if done.scene else
            "without a Foxglove view (the recording names no scene)")
    print(f"wrote {args.output}: {done.messages} messages, JSON-encoded, {view}", flush=True)
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add `record`, `play`, `bag` and `export` to the `twinfleet` subcommands."""
    _add_record(sub)
    _add_play(sub)
    _add_bag(sub)
    _add_export(sub)


def _add_record(sub: argparse._SubParsersAction) -> None:
    """`twinfleet record [SCENARIO] -o FILE`."""
    r = sub.add_parser("record", help="record every fleet topic to an MCAP file")
    r.add_argument("scenario", nargs="?", default=None,
                   help="scenario YAML to launch and record (omit to record a running fleet "
                        "given with --connect)")
    r.add_argument("-o", "--output", required=True, metavar="FILE",
                   help="MCAP file to write, e.g. run.mcap")
    r.add_argument("--duration", type=float, default=None, metavar="S",
                   help="stop after S wall seconds (default: with a SCENARIO, when the run ends; "
                        "with --connect, at Ctrl-C)")
    r.add_argument("--connect", default=None, metavar="EP",
                   help="record the running fleet behind this Zenoh router (default without "
                        "SCENARIO: $TWINFLEET_CONNECT, else the fleet running on this machine)")
    r.add_argument("--fleet", default=env_value(EnvVar.FLEET) or "*",
                   help="with --connect: the fleet to record, '*' for every fleet "
                        "(default: $TWINFLEET_FLEET or %(default)s)")
    r.add_argument("--credentials", metavar="FILE",
                   default=env_value(EnvVar.CREDENTIALS),
                   help="with --connect: the fleet's credentials, a copy of its fleet registry "
                        "entry (owner-only JSON; default: $TWINFLEET_CREDENTIALS, else this "
                        "machine's registry, read again when the fleet is launched again)")
    r.add_argument("--time-scale", type=float, default=None, metavar="K",
                   help="with a SCENARIO: run fleet time K times faster (default: live.time_scale or 1)")
    r.add_argument("--seed", type=int, default=None,
                   help="with a SCENARIO: fleet seed (default: the scenario's)")
    r.add_argument("--listen", default=None, metavar="EP",
                   help="with a SCENARIO: endpoint of the recorder's router, which the fleet joins "
                        "(default: tcp/127.0.0.1:<free port>)")
    r.add_argument("--module", action="append", default=[], metavar="MODULE",
                   help="import MODULE first so its message classes give exact schemas (repeatable; "
                        "a SCENARIO imports its nodes' messages itself, and with --connect the "
                        "running nodes serve theirs; needed only for types no node knows)")
    add_wait_arguments(r, "record it from its first message (without a SCENARIO)")
    r.set_defaults(func=cmd_record)


def _add_play(sub: argparse._SubParsersAction) -> None:
    """`twinfleet play FILE`."""
    p = sub.add_parser("play", help="re-publish an MCAP recording onto Zenoh")
    p.add_argument("file", help="MCAP file written by `twinfleet record`")
    p.add_argument("--rate", type=float, default=1.0, metavar="K",
                   help="playback speed factor: 1 = as recorded, 2 = twice as fast (default: 1)")
    p.add_argument("--listen", default=None, metavar="EP",
                   help="be the router on EP (e.g. tcp/127.0.0.1:7447) instead of joining --connect")
    p.add_argument("--wait", type=float, default=2.0, metavar="S",
                   help="wait up to S seconds for a subscriber to match before playing "
                        "(default: %(default)s)")
    p.add_argument("--into-fleet", action="store_true",
                   help="inject the recording into a running fleet on purpose: join it with "
                        "its credentials and sign every message as recorded input, which "
                        "only a fleet launched with --accept-recorded takes (its result then "
                        "says so); without this flag a fleet drops what play publishes")
    add_connection_arguments(p, fleet_help="publish into this fleet; '*' keeps the recorded fleet")
    p.set_defaults(func=cmd_play)
    p.description = ("Re-publish a recording at its recorded pace. Without --connect, play is "
                     "its own Zenoh router on a free port and registers the recorded fleet, so "
                     "`twinfleet topic echo /poses` (or view, foxglove) finds it.")


def _add_bag(sub: argparse._SubParsersAction) -> None:
    """`twinfleet bag info FILE` and `twinfleet bag repair FILE`."""
    bag = sub.add_parser("bag", help="inspect recordings (ros2 bag style)")
    bs = bag.add_subparsers(dest="action", required=True, metavar="ACTION")
    bi = bs.add_parser("info", help="summarise a recording: duration, messages per topic, schemas",
                       description="Summarise an MCAP recording: duration, start and end, "
                                   "message count per topic and type, schemas.")
    bi.add_argument("file", help="MCAP file, e.g. run.mcap, or a rosbag2 folder "
                                 "(`twinfleet export --ros2`)")
    bi.set_defaults(func=cmd_bag)
    _file_command(bs, "repair", cmd_bag,
                  "make a recording cut short (recorder killed, disk full) complete again",
                  "Read every complete chunk of an MCAP recording whose recorder died (kill -9) "
                  "or ran out of disk, and write them as a complete recording (summary and index "
                  "included), in place or to -o FILE. The recorder flushes a chunk at least twice "
                  "a second, so at most the last half second is lost.",
                  ("MCAP file, e.g. run.mcap", "write the repaired copy here (default: replace "
                   "FILE)"), required=False)


def _add_export(sub: argparse._SubParsersAction) -> None:
    """`twinfleet export FILE -o OUT`."""
    _file_command(sub, "export", cmd_export,
                  "write a copy of a recording that Foxglove draws as it is",
                  "Copy an MCAP file written by `twinfleet record` with every message as JSON "
                  "(bytes as base64) and schemas to match, plus Foxglove's well-known messages on "
                  "/foxglove/... channels (foxglove.Grid map, foxglove.SceneUpdate robots and "
                  "collisions, foxglove.PointCloud scans), so Foxglove's 3D panel draws it with "
                  "no configuration. `twinfleet play` needs the original (msgpack) recording.",
                  ("MCAP file written by `twinfleet record`",
                   "JSON-encoded MCAP file to write, e.g. run.json.mcap; with --ros2 the "
                   "rosbag2 folder to create, e.g. run_bag/"), required=True)
    export = sub.choices["export"]
    export.add_argument("--ros2", action="store_true",
                        help="write a rosbag2 folder instead (metadata.yaml + MCAP, ROS 2 standard "
                             "types in CDR) for `ros2 bag info/play`; needs twinfleet[ros2]")
    export.add_argument("--mapping", "--ros2-mapping", default=None, metavar="MODULE:NAME",
                        help="with --ros2: the fleet's ROS 2 mapping, its module found in the "
                             "working directory too (default: the one the recording's scene "
                             "names, else none: every message by its fields)")


def _file_command(parent: argparse._SubParsersAction, name: str, func: Any, text: str,
                  description: str, helps: tuple[str, str], *, required: bool) -> None:
    """A command taking FILE and -o/--output FILE (`helps`: their help texts)."""
    p = parent.add_parser(name, help=text, description=description)
    p.add_argument("file", help=helps[0])
    p.add_argument("-o", "--output", required=required, default=None, metavar="FILE",
                   help=helps[1])
    p.set_defaults(func=func)
