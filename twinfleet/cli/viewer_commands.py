"""`twinfleet view` and `twinfleet foxglove`: the browser-facing viewers of a fleet.

    twinfleet view [--port P] [--trace FILE]      twinfleet foxglove [--port P]

Both serve on 127.0.0.1 and answer only their own host names, their own origins and the
per-run token of the URL they print (`runtime.tools.view.web_guard`). Their engines are
imported when the command runs.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from twinfleet.runtime.access.connection import (
    CommandError,
    add_connection_arguments,
    add_wait_arguments,
    connection,
    error_prefix,
)


def register(sub: argparse._SubParsersAction) -> None:
    """Add `view` and `foxglove` to the `twinfleet` command line."""
    _view_parser(sub)
    _foxglove_parser(sub)


def cmd_view(args: argparse.Namespace) -> int:
    """`twinfleet view`: serve the live viewer (or a trace) on 127.0.0.1."""
    from twinfleet.runtime.tools.view.viewer import run_viewer

    connect, fleet, auth = args.connect, args.fleet, None
    if args.trace is None and args.credentials:  # a fleet of another machine: its secrets
        conn = connection(args)
        connect, fleet, auth = conn.endpoint, conn.fleet, conn.auth
    elif args.trace is None and not connect:
        from twinfleet.runtime.access.registry import running_fleets

        if any(fleet in ("*", e.fleet) for e in running_fleets()):
            conn = connection(args)  # one fleet: that one; several: the one-line question
            connect, fleet = conn.endpoint, conn.fleet
    try:
        return run_viewer(connect=connect, fleet=fleet, port=args.port, trace_path=args.trace,
                          auth=auth, web=web_access(args))
    except (ValueError, KeyError, OSError) as exc:
        print(f"{error_prefix(args)} {exc}", file=sys.stderr)
        return 2


def cmd_foxglove(args: argparse.Namespace) -> int:
    """`twinfleet foxglove`: a Foxglove WebSocket server showing the fleet."""
    from twinfleet.runtime.tools.view.foxglove_bridge import run_foxglove

    conn = connection(args)
    try:
        return run_foxglove(conn.endpoint, conn.fleet, port=args.port,
                            auth=conn.auth if args.credentials else None,
                            web=web_access(args, foxglove_app=args.allow_foxglove_app))
    except (RuntimeError, OSError) as exc:  # the port is taken
        raise CommandError(f"foxglove: cannot serve on 127.0.0.1:{args.port}: {exc}") from None


def web_access(args: argparse.Namespace, *, foxglove_app: bool = False) -> Any:
    """Who a browser-facing command's server answers (`runtime.tools.view.web_guard`)."""
    from twinfleet.runtime.tools.view.web_guard import FOXGLOVE_APP_ORIGIN, WebAccess

    origins = [*args.allow_origin, *([FOXGLOVE_APP_ORIGIN] if foxglove_app else [])]
    return WebAccess.allowing(args.allow_host, origins)


def _add_web_arguments(p: argparse.ArgumentParser) -> None:
    """--allow-host and --allow-origin of a browser-facing server."""
    group = p.add_argument_group("browser access (the printed URL carries a per-run token; "
                                 "requests without it, for another Host, or from a page of "
                                 "another origin are refused)")
    group.add_argument("--allow-host", action="append", default=[], metavar="NAME",
                       help="also answer requests for Host NAME (default: 127.0.0.1, "
                            "localhost and ::1 only; repeatable)")
    group.add_argument("--allow-origin", action="append", default=[], metavar="ORIGIN",
                       help="also accept WebSockets and requests from pages of ORIGIN, e.g. "
                            "https://example.org (default: the server's own pages only; "
                            "repeatable)")


def _foxglove_parser(sub: argparse._SubParsersAction) -> None:
    text = ("serve the live fleet to Foxglove (WebSocket, subprotocol foxglove.sdk.v1): the map "
            "as a grid, robots as scene entities, scans as point clouds, every topic as JSON")
    p = sub.add_parser("foxglove", help=text, description=text[0].upper() + text[1:] + ". In "
                       "Foxglove: Open connection, ws://127.0.0.1:PORT; the 3D panel draws the "
                       "fleet in frame 'map' with no configuration. The server is foxglove-sdk's, "
                       "which accepts only the subprotocol name foxglove.sdk.v1 (offered by "
                       "current Foxglove releases); a client that offers only the older name "
                       "foxglove.websocket.v1 (older Foxglove and Lichtblick builds) is refused "
                       "at the handshake (HTTP 400).")
    p.add_argument("--port", type=int, default=None, metavar="P",
                   help="TCP port on 127.0.0.1; 0 picks a free one (default: 8765, Foxglove's "
                        "usual one, or a free one when 8765 is taken: the URL is printed)")
    p.add_argument("--allow-foxglove-app", action="store_true",
                   help="accept connections from Foxglove's web app (origin "
                        "https://app.foxglove.dev); a refused client's line names its origin, "
                        "for --allow-origin")
    _add_web_arguments(p)
    add_connection_arguments(p)
    add_wait_arguments(p, "serve it once its router is found")
    p.set_defaults(func=cmd_foxglove)


def _view_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("view", help="web page on 127.0.0.1 showing a live fleet, or stepping "
                                    "through a checker trace")
    p.add_argument("--port", type=int, default=8765, metavar="P",
                   help="TCP port of the page on 127.0.0.1; 0 picks a free one (default: %(default)s)")
    p.add_argument("--trace", default=None, metavar="FILE",
                   help="step through this checker trace JSON (from `twinfleet check --trace-out`) "
                        "instead of watching a live fleet")
    _add_web_arguments(p)
    add_connection_arguments(p, fleet_help="fleet to show; '*' shows the first fleet whose data "
                             "arrives")
    p.set_defaults(func=cmd_view)
