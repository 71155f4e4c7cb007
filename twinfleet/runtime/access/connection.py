"""Argument helpers shared by every layer's commands: connection options, message arguments,
the one-line error type.

Connection options are defined once (`add_connection_arguments`). Without
``--connect`` (or $TWINFLEET_CONNECT) a command finds the fleet in the
per-user fleet registry (`runtime.access.registry`): the only running fleet, or the
one named by ``--fleet``. `connection(args)` resolves that into an endpoint
and a fleet name, or raises `CommandError`. Nothing here imports Zenoh until
a command runs.

`CommandError` is how a command says "bad input or no answer": `twinfleet.cli`
prints its text as one line on stderr and exits with its code (2) (`errors`, imported
here too).
"""

from __future__ import annotations

import argparse
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from twinfleet.runtime.access.errors import CommandError, error_prefix  # noqa: F401 (here too)
from twinfleet.runtime.access.fleetauth import (
    CredentialsError,
    MonitorAuth,
    login_settings,
    monitor_auth,
    read_credentials,
    registry_auth,
    secure,
)
from twinfleet.runtime.contract.environment import EnvVar, env_value
from twinfleet.runtime.contract.kinds import (  # noqa: F401 (the commands' exit codes, from here too)
    EXIT_BAD_INPUT,
    EXIT_CONTRACT_BREACH,
    EXIT_FAILED,
    EXIT_INCONCLUSIVE,
    EXIT_INTERRUPTED,
    EXIT_OK,
)

DISCOVERY_S = 1.0
WAIT_POLL_S = 0.1  # how often --wait looks at the fleet registry again


_RUST_WHERE = re.compile(r"\s*at /\S+?\.rs:\d+\.?")


def zenoh_error_text(exc: BaseException) -> str:
    """A `zenoh.ZError` as one line, without the Rust source locations it carries."""
    text = _RUST_WHERE.sub("", str(exc)).strip()
    return " ".join(text.split()).rstrip(".!] ").replace("[", "")


def unreachable_hint(endpoint: str, auth: MonitorAuth | None, *, registry: bool = False) -> str:
    """What to check when the router at `endpoint` refused or did not answer (one clause)."""
    if secure(endpoint) and (auth is None or auth.tls_ca is None):
        return ("a tls/quic fleet is reached with its certificate authority: pass --credentials "
                "FILE, a copy of its registry entry on the machine that launched it")
    if secure(endpoint):
        return ("is the fleet running there, and are the --credentials its current ones? A "
                "relaunch makes new certificates, and the TLS handshake fails with another "
                "launch's authority: copy its registry entry again")
    return ("the fleet registry names it, but its launcher does not answer" if registry
            else "is a fleet running there?")


@dataclass(frozen=True)
class Connection:
    """Where a monitor command connects: an endpoint, the fleet, and how it was found."""

    endpoint: str
    fleet: str
    found: str  # "--connect" | "registry"
    auth: MonitorAuth = field(default_factory=MonitorAuth)  # logins and fleet key, if any


def add_connection_arguments(parser: argparse.ArgumentParser, *,
                             fleet_help: str = "fleet name (the scenario's name); '*' means every "
                                               "fleet behind --connect",
                             discovery: bool = False) -> None:
    """Add --connect and --fleet (and, with `discovery`, --query-timeout) to a command."""
    group = parser.add_argument_group("connection")
    group.add_argument("--connect", metavar="EP", default=env_value(EnvVar.CONNECT),
                       help="Zenoh endpoint of the fleet's router, e.g. tcp/10.0.0.2:7447 "
                            "(default: $TWINFLEET_CONNECT, else the fleet running on this machine, "
                            "found in the fleet registry)")
    group.add_argument("--fleet", default=env_value(EnvVar.FLEET) or "*",
                       help=fleet_help + " (default: $TWINFLEET_FLEET or %(default)s)")
    group.add_argument("--credentials", metavar="FILE",
                       default=env_value(EnvVar.CREDENTIALS),
                       help="the fleet's credentials: a copy of its fleet registry entry (owner-"
                            "only JSON; default: $TWINFLEET_CREDENTIALS, else the registry's "
                            "entry for the fleet or endpoint)")
    if discovery:
        group.add_argument("--query-timeout", type=float, default=DISCOVERY_S, metavar="S",
                           help="seconds to wait for discovery answers (default: %(default)s)")


def add_wait_arguments(parser: argparse.ArgumentParser, what: str) -> None:
    """Add --wait (wait for a fleet to be launched, and for `what`) and --wait-timeout."""
    parser.add_argument("--wait", action="store_true",
                        help="wait for a fleet to be launched when none runs yet (found in the "
                        f"fleet registry; said once on stderr), and {what}; default: exit 2 "
                        "at once")
    parser.add_argument("--wait-timeout", type=float, default=None, metavar="S",
                        help="with --wait, give up after S seconds (exit 2; default: wait "
                             "until Ctrl-C)")


def _await_fleet(fleet: str, timeout_s: float | None) -> Any:
    """The registry entry of `fleet` (``*``: any), waiting until one is launched; says so
    once on stderr. Raises `RegistryError` when `timeout_s` passes first."""
    import sys
    import time

    from twinfleet.runtime.access.registry import RegistryError, find_fleet, running_fleets

    deadline = None if timeout_s is None else time.monotonic() + timeout_s
    said = False
    while True:
        matching = [e for e in running_fleets() if fleet in ("*", e.fleet)]
        if matching:
            return find_fleet(fleet, matching)
        if deadline is not None and time.monotonic() >= deadline:
            raise RegistryError(f"no fleet{'' if fleet == '*' else f' named {fleet!r}'} was "
                                f"launched on this machine within {timeout_s:g} s")
        if not said:
            print(f"waiting for {'a fleet' if fleet == '*' else f'fleet {fleet!r}'} to be "
                  "launched on this machine" + (f" (up to {timeout_s:g} s)" if timeout_s
                                                 is not None else " (Ctrl-C to stop)"),
                  file=sys.stderr, flush=True)
            said = True
        time.sleep(WAIT_POLL_S)


def connection(args: argparse.Namespace) -> Connection:
    """The endpoint and fleet of a command's --connect/--fleet, or of the registry (with
    ``--wait``, once a matching fleet is launched: `add_wait_arguments`).

    Raises:
        CommandError: no --connect and the registry has no single matching fleet.
    """
    from twinfleet.runtime.access.registry import RegistryError, find_fleet

    try:
        given = getattr(args, "credentials", None)
        endpoint, auth = read_credentials(given) if given else (None, None)
        if args.connect:
            if auth is None:  # a fleet of this machine behind that endpoint: its secrets
                auth = registry_auth(args.connect)
            return Connection(args.connect, args.fleet, "--connect", auth)
        if endpoint and auth is not None:
            return Connection(endpoint, args.fleet, "--credentials", auth)
        if getattr(args, "wait", False) is True:
            entry = _await_fleet(args.fleet, getattr(args, "wait_timeout", None))
        else:
            entry = find_fleet(args.fleet)
        return Connection(entry.endpoint, entry.fleet, "registry", monitor_auth(entry.extra))
    except (RegistryError, CredentialsError) as exc:
        raise CommandError(str(exc)) from None


def zenoh_conf(endpoint: str, auth: MonitorAuth | None = None, *,
               write: bool = False) -> Any:
    """The client Zenoh config of a monitor command connecting to `endpoint` (with the
    operator login when it publishes or calls, `write`, else the read-only one)."""
    from twinfleet.runtime.host.zenoh_transport import zenoh_config

    try:
        return zenoh_config(connect=[endpoint], mode="client",
                            settings=login_settings(auth, write=write) if auth else None)
    except ValueError as exc:
        raise CommandError(str(exc)) from None


def need_fleet(args: argparse.Namespace, conn: Connection) -> str:
    """The single fleet a command that publishes or calls needs (not '*')."""
    if conn.fleet == "*":
        raise CommandError(f"{args.command} {args.action} needs --fleet NAME (or $TWINFLEET_FLEET)"
                           f" to know which fleet behind {conn.endpoint} to address")
    return conn.fleet


def import_modules(modules: Sequence[str]) -> None:
    """Import each named module (so that its message types are registered)."""
    import importlib

    for name in modules:
        try:
            importlib.import_module(name)
        except ImportError as exc:
            raise CommandError(f"--module {name}: cannot import it ({exc})") from None


def add_message_arguments(p: argparse.ArgumentParser) -> None:
    """Add TYPE, DATA and --module to `topic pub` / `service call`."""
    p.add_argument("type", help="message type name, e.g. std_msgs/String (ROS 2 spelling "
                                "std_msgs/msg/String works too)")
    p.add_argument("data", nargs="?", default="",
                   help="message fields as YAML, e.g. \"{data: hello}\" (default: no fields)")
    p.add_argument("--module", action="append", default=[], metavar="MODULE",
                   help="import MODULE first so its message types are known here (repeatable; "
                        "types the fleet's nodes know are learned from them)")
    p.add_argument("--force", action="store_true",
                   help="send even when the fleet's nodes say the name carries another type "
                        "(refused by default, naming both types); the nodes refuse the "
                        "message, and a live verdict names it as external input")
