"""Argument helpers shared by every layer's commands: connection options, message arguments.

Connection options are defined once (`add_connection_arguments`); `--connect`
defaults to $TWINFLEET_CONNECT and `--fleet` to $TWINFLEET_FLEET. Nothing here
imports Zenoh until a command runs.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence

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


def zenoh_conf(args: argparse.Namespace):  # noqa: ANN201 - zenoh imported lazily
    """The client Zenoh config for a monitor command's --connect."""
    from twinfleet.runtime.zenoh_transport import zenoh_config

    return zenoh_config(connect=[args.connect], mode="client")


def need_fleet(args: argparse.Namespace) -> str | None:
    """The --fleet a command that publishes needs, or None (after saying so) for '*'."""
    if args.fleet == "*":
        print(f"error: {args.command} {args.action} needs --fleet NAME (or $TWINFLEET_FLEET)",
              file=sys.stderr)
        return None
    return args.fleet


def import_modules(modules: Sequence[str]) -> None:
    """Import each named module (so that its message types are registered)."""
    import importlib

    for name in modules:
        importlib.import_module(name)


def add_message_arguments(p: argparse.ArgumentParser) -> None:
    """Add TYPE, DATA and --module to `topic pub` / `service call`."""
    p.add_argument("type", help="message type name, e.g. std_msgs/String")
    p.add_argument("data", nargs="?", default="",
                   help="message fields as YAML, e.g. \"{data: hello}\" (default: no fields)")
    p.add_argument("--module", action="append", default=[], metavar="MODULE",
                   help="import MODULE first so its message types are validated (repeatable)")
