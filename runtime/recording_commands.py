"""`twinfleet record`, `play` and `export`: fleet topics to MCAP files and back.

The engines live in `runtime.recorder` (record, play) and `runtime.mcap_export`
(the JSON copy for Foxglove); this module is their argparse layer.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import sys

from twinfleet.runtime.cliargs import add_connection_arguments, import_modules


def cmd_record(args: argparse.Namespace) -> int:
    """`twinfleet record`: launch a scenario (or join a fleet) and write its topics to MCAP."""
    import zenoh

    from twinfleet.runtime import recorder
    from twinfleet.runtime.launcher import format_result
    from twinfleet.runtime.scenario import ScenarioError, load_scenario

    import_modules(args.module)
    if args.scenario is not None and args.connect:
        print("error: give a SCENARIO to launch or --connect EP of a running fleet, not both "
              "(with a SCENARIO the recorder is the fleet's router: see --listen)", file=sys.stderr)
        return 2
    connect = args.connect or os.environ.get("TWINFLEET_CONNECT")
    try:
        if args.scenario is None:
            if not connect:
                print("error: record needs a SCENARIO to launch or --connect EP of a running "
                      "fleet", file=sys.stderr)
                return 2
            result, rec = None, asyncio.run(recorder.record_live(
                connect, args.fleet, args.output, duration_s=args.duration, handle_signals=True))
        else:
            result, rec = asyncio.run(recorder.record_scenario(
                load_scenario(args.scenario), args.output, time_scale=args.time_scale,
                duration_s=args.duration, seed=args.seed, listen=args.listen))
    except (ScenarioError, OSError, zenoh.ZError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for line in format_result(result) if result is not None else ():
        print(f"[launcher] {line}", flush=True)
    print(f"wrote {args.output}: {rec.messages} messages on {rec.topics} topics", flush=True)
    return 0 if result is None or result.passed else 1


def cmd_play(args: argparse.Namespace) -> int:
    """`twinfleet play`: re-publish a recording onto Zenoh."""
    from twinfleet.runtime.recorder import play
    from twinfleet.runtime.zenoh_transport import zenoh_config

    if args.listen:
        def make_config():  # noqa: ANN202 - zenoh imported lazily
            return zenoh_config(listen=[args.listen], mode="router")
    else:
        def make_config():  # noqa: ANN202 - zenoh imported lazily
            return zenoh_config(connect=[args.connect], mode="client")
    import zenoh

    try:
        return play(make_config, args.file, rate=args.rate,
                    fleet=None if args.fleet == "*" else args.fleet, wait_s=args.wait)
    except (ValueError, OSError, zenoh.ZError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


def cmd_export(args: argparse.Namespace) -> int:
    """`twinfleet export`: a JSON-encoded copy of a recording."""
    from mcap.exceptions import McapError

    from twinfleet.runtime.mcap_export import export_json

    try:
        count = export_json(args.file, args.output)
    except (ValueError, OSError, McapError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {args.output}: {count} messages, JSON-encoded", flush=True)
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add `record`, `play` and `export` to the `twinfleet` subcommands."""
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
                   help="record the running fleet behind this Zenoh router "
                        "(default without SCENARIO: $TWINFLEET_CONNECT)")
    r.add_argument("--fleet", default=os.environ.get("TWINFLEET_FLEET", "*"),
                   help="with --connect: the fleet to record, '*' for every fleet "
                        "(default: $TWINFLEET_FLEET or %(default)s)")
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
    r.set_defaults(func=cmd_record)
    p = sub.add_parser("play", help="re-publish an MCAP recording onto Zenoh")
    p.add_argument("file", help="MCAP file written by `twinfleet record`")
    p.add_argument("--rate", type=float, default=1.0, metavar="K",
                   help="playback speed factor: 1 = as recorded, 2 = twice as fast (default: 1)")
    p.add_argument("--listen", default=None, metavar="EP",
                   help="be the router on EP (e.g. tcp/127.0.0.1:7447) instead of joining --connect")
    p.add_argument("--wait", type=float, default=2.0, metavar="S",
                   help="wait up to S seconds for a subscriber to match before playing "
                        "(default: %(default)s)")
    add_connection_arguments(p, fleet_help="publish into this fleet; '*' keeps the recorded fleet",
                             discovery=False)
    p.set_defaults(func=cmd_play)
    e = sub.add_parser("export", help="write a JSON-encoded copy of a recording (for Foxglove)",
                       description="Copy an MCAP file written by `twinfleet record` with every "
                                   "message as JSON (bytes as base64) and schemas to match, so "
                                   "that viewers like Foxglove Studio decode it. `twinfleet play` "
                                   "needs the original (msgpack) recording.")
    e.add_argument("file", help="MCAP file written by `twinfleet record`")
    e.add_argument("-o", "--output", required=True, metavar="FILE",
                   help="JSON-encoded MCAP file to write, e.g. run.json.mcap")
    e.set_defaults(func=cmd_export)
