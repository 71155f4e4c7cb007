"""Entry point of one node process: ``python -m twinfleet.runtime.fleet.node_main --scenario F --node NAME ...``.

Loads the scenario, builds the node, opens one Zenoh session (client of the
launcher's router, or of any router given with ``--connect``), runs a
`NodeHost` until SIGTERM/SIGINT, then undeclares and closes the session with a
watchdog so a hung close cannot keep the process alive. Exit code 0, 1 when
the node stopped on a handler error (``live.stop_on_error``), 2 on bad input.

The process also serves its statistics on ``twinfleet/<fleet>/@stats/<node>``
(`NodeStatistics.to_dict` as a msgpack map), which the launcher and `twinfleet node
list --stats` read back with `NodeStatistics.from_dict`, and the JSON
Schemas of the message classes it knows on ``twinfleet/<fleet>/@types/<node>``
(a JSON map type name → schema), which `twinfleet record --connect` reads.

``--record-events FILE`` logs every handler run to FILE as JSON lines
(`runtime.core.eventlog.EventLog`, an observer of the node core); ``--gate`` runs the
node under a replay coordinator: logical time, and only granted events run
(`runtime.host.replay_gate.ReplayGate`).
"""

# ruff: noqa: E402 - the stop handlers go in before the slow imports (below)
from __future__ import annotations

import signal
import sys

if __name__ == "__main__":
    # The launcher may stop the fleet while this process still imports (zenoh, the user's
    # module: seconds on a loaded machine); it then leaves quietly, exit code 0, not with a
    # KeyboardInterrupt traceback that reads like a failure. `main` keeps these handlers
    # until the event loop installs its own.
    for _sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(_sig, lambda *_: sys.exit(0))

import argparse
import asyncio
import ctypes
import faulthandler
import json
import os
from collections.abc import Sequence

import msgpack

from twinfleet.runtime.access.fleetauth import accepts_recorded, node_secrets, node_tls
from twinfleet.runtime.contract.environment import EnvVar, env_value
from twinfleet.runtime.contract.node import QOS_DEFAULT, Node
from twinfleet.runtime.core.eventlog import EventLog
from twinfleet.runtime.core.guard import BRIDGE_KEY_ENV, key_from_env
from twinfleet.runtime.core.state_report import StateReporter
from twinfleet.runtime.core.statistics import NodeStatistics, StatisticsError
from twinfleet.runtime.host.clock import Clock, FleetClock
from twinfleet.runtime.host.introspect import PARAM_FLAG, load_with_params, serve_info
from twinfleet.runtime.host.keys import KeyKind, node_key, topic_key
from twinfleet.runtime.host.node_host import NodeHost
from twinfleet.runtime.host.replay_gate import LogicalClock
from twinfleet.runtime.host.schemas import registered_schemas
from twinfleet.runtime.host.transport import Respond
from twinfleet.runtime.host.zenoh_transport import ZenohTransport, zenoh_config
from twinfleet.runtime.scenario.spec import NodeConfig, Scenario, ScenarioError

_PR_SET_PDEATHSIG = 1
PARENT_ENV = EnvVar.LAUNCHER_PID
LIMIT_ENV = EnvVar.MAX_PAYLOAD  # bytes a sample may have (set by the launcher)


def die_with_parent() -> None:
    """Ask Linux to SIGTERM this process when the launcher dies (even by SIGKILL)."""
    expected = env_value(PARENT_ENV)
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)
    except (OSError, AttributeError):
        return  # not Linux: rely on the launcher's shutdown
    if expected is not None and os.getppid() != int(expected):
        sys.exit(0)  # the launcher died before prctl took effect


def statistics_payload(stats: NodeStatistics) -> bytes:
    """The answer of the statistics queryable: `NodeStatistics.to_dict` as msgpack."""
    return msgpack.packb(stats.to_dict())


def read_statistics(payload: bytes) -> NodeStatistics:
    """A statistics queryable's answer (`statistics_payload`) as a record.

    Raises:
        StatisticsError: not a msgpack map, or not the counters of this version.
    """
    try:
        data = msgpack.unpackb(payload, raw=False)
    except Exception as exc:  # msgpack raises several unrelated types for bad input
        raise StatisticsError(f"node statistics: not a msgpack map ({exc})") from None
    return NodeStatistics.from_dict(data)


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    """Parse the node process's command line."""
    p = argparse.ArgumentParser(prog="python -m twinfleet.runtime.fleet.node_main",
                                description="Run one twinfleet node (normally started by the launcher).")
    p.add_argument("--scenario", required=True, help="scenario YAML file")
    p.add_argument("--node", required=True, help="name of the node entry to run")
    p.add_argument("--connect", required=True, help="Zenoh endpoint of the router, e.g. tcp/127.0.0.1:7447")
    p.add_argument("--epoch-ns", type=int, default=None,
                   help="fleet epoch as time.time_ns() (default: now)")
    p.add_argument("--time-scale", type=float, default=None,
                   help="fleet ms per wall ms (default: scenario live.time_scale or 1)")
    p.add_argument("--seed", type=int, default=None, help="fleet seed (default: scenario seed)")
    p.add_argument("--stop-on-error", action="store_true", default=None,
                   help="exit with code 1 at the first handler exception")
    p.add_argument("--no-wait", action="store_true",
                   help="run @on_start without waiting for the other nodes of the scenario")
    p.add_argument("--fleet-epoch", action="store_true",
                   help="wait for the launcher's epoch token and run @on_start at fleet time 0 "
                        "(the launcher declares it once every node is alive)")
    p.add_argument("--restarted", action="store_true",
                   help="this process respawns a node that died: @on_start runs at the "
                        "fleet time it restarts at")
    p.add_argument("--verbose", action="store_true",
                   help="print every counter at the end (default: only when something went "
                        "wrong)")
    p.add_argument("--close-timeout", type=float, default=5.0,
                   help="seconds allowed for closing Zenoh before the process is forced out")
    p.add_argument("--record-events", default=None, metavar="FILE",
                   help="append every dispatched event to FILE as JSON lines, flushed per line")
    p.add_argument(PARAM_FLAG, action="append", default=[], metavar="[NODE.]NAME=VALUE",
                   help="parameter override, as `twinfleet launch --param` (repeatable)")
    p.add_argument("--report", choices=("states", "failures"), default=None,
                   help="publish a state report after each handler that changed the state or "
                        "failed (states), or only after failures (failures), for the launcher's "
                        "live verdict (runtime.core.state_report)")
    p.add_argument("--stall-ms", type=int, default=None, metavar="MS",
                   help="count a timer released more than MS fleet ms late as a stall")
    p.add_argument("--gate", action="store_true",
                   help="replay mode: logical time, and run only the events a replay "
                        "coordinator grants (twinfleet replay --live)")
    return p.parse_args(argv)


async def run_node(args: argparse.Namespace, scenario: Scenario) -> int:
    """Run the node until a signal or stop_on_error; return the exit code."""
    cfg = scenario.node(args.node)
    node = cfg.instantiate()
    live = scenario.live
    time_scale = args.time_scale if args.time_scale is not None else live.time_scale
    clock: Clock = LogicalClock() if args.gate else FleetClock(args.epoch_ns, time_scale)
    try:
        transport = _transport(args, external_keys(scenario.fleet, node))
    except ValueError as exc:  # a bad TWINFLEET_ZENOH_CONFIG_OVERRIDE or secret
        print(f"error: {exc}", file=sys.stderr)
        return 2
    seed = args.seed if args.seed is not None else scenario.seed
    events = _event_log(args, scenario, node.name, seed, time_scale, clock)
    host = _host(args, scenario, node, transport, clock, seed, events)
    stopping = _stop_on_signals(host)
    await transport.open()
    if stopping.is_set():
        await transport.close()
        return 0
    _serve(args, scenario, cfg, host, transport)
    try:
        await host.run()
    finally:
        faulthandler.dump_traceback_later(args.close_timeout, exit=True)
        await transport.close()
        faulthandler.cancel_dump_traceback_later()
        if events is not None:
            events.close()
    statistics = host.statistics()
    if args.verbose or host.failed or statistics.troubled():  # else the launcher's table says it
        print(f"stopped: {statistics.line()}", file=sys.stderr, flush=True)
    return 1 if host.failed else 0


def external_keys(fleet: str, node: Node) -> frozenset[str]:
    """The data keys of the topics `node` takes from outside the fleet (its class's
    ``external_topics``: `runtime.core.guard`)."""
    return frozenset(topic_key(fleet, node.resolve(t)) for t in getattr(node, "external_topics", ()))


def _transport(args: argparse.Namespace, external: frozenset[str]) -> ZenohTransport:
    """The node's Zenoh transport: a client of ``--connect`` with the login, payload limit
    and bridge key the launcher put in the environment; ValueError for a bad secret or
    override."""
    login, key = node_secrets()
    bridge_key = key_from_env(name=BRIDGE_KEY_ENV)
    limit_text = env_value(LIMIT_ENV)
    limit = int(limit_text) if limit_text else None
    settings = {**(login.settings() if login else {}), **node_tls()}
    if limit is not None:  # Zenoh itself refuses larger frames (the router does too)
        settings["transport/link/rx/max_message_size"] = limit + 1024
    config = zenoh_config(connect=[args.connect], settings=settings)
    return ZenohTransport(config, key=key, limit=limit, bridge_key=bridge_key,
                          external=external if bridge_key is not None else frozenset(),
                          accept_recorded=accepts_recorded())


def _event_log(args: argparse.Namespace, scenario: Scenario, name: str, seed: int,
               time_scale: float, clock: Clock) -> EventLog | None:
    """The event log ``--record-events`` asks for, or None."""
    if not args.record_events:
        return None
    return EventLog(args.record_events, node=name, scenario=str(scenario.path),
                    seed=seed, time_scale=time_scale, epoch_ns=getattr(clock, "epoch_ns", None),
                    gated=bool(args.gate))


def _host(args: argparse.Namespace, scenario: Scenario, node: Node, transport: ZenohTransport,
          clock: Clock, seed: int, events: EventLog | None) -> NodeHost:
    """The node's host loop as the command line and the scenario's live settings say."""
    stop_on_error = bool(args.stop_on_error if args.stop_on_error is not None
                         else scenario.live.stop_on_error)
    peers = () if args.no_wait else tuple(n.name for n in scenario.nodes)
    return NodeHost(node, transport, clock, seed=seed, fleet=scenario.fleet,
                    stop_on_error=stop_on_error, wait_for=peers, events=events,
                    gated=bool(args.gate), stall_ms=args.stall_ms,
                    fleet_epoch=args.fleet_epoch and not args.gate, restarted=args.restarted)


def _stop_on_signals(host: NodeHost) -> asyncio.Event:
    """Stop `host` on SIGINT or SIGTERM; the event tells a signal that came before the
    session was open."""
    stopping = asyncio.Event()

    def on_signal() -> None:
        stopping.set()
        host.stop()

    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, on_signal)
    return stopping


def _serve(args: argparse.Namespace, scenario: Scenario, cfg: NodeConfig, host: NodeHost,
           transport: ZenohTransport) -> None:
    """Declare what the process answers besides the node's own services: its statistics,
    its message schemas and its description, and (``--report``) its state reports."""
    node = host.node

    def serve_stats(_payload: bytes, respond: Respond) -> None:
        respond(statistics_payload(host.statistics()), "")

    transport.serve(node_key(scenario.fleet, KeyKind.STATS, node.name), serve_stats)
    if args.report is not None:
        put = transport.publisher(node_key(scenario.fleet, KeyKind.STATE, node.name), QOS_DEFAULT)
        host.core.observe(StateReporter(node, put, states=args.report == "states"))

    def serve_types(_payload: bytes, respond: Respond) -> None:
        respond(json.dumps(registered_schemas()).encode(), "")

    transport.serve(node_key(scenario.fleet, KeyKind.TYPES, node.name), serve_types)
    serve_info(transport, scenario.fleet, node, cfg.class_path)


def main(argv: Sequence[str] | None = None) -> int:
    """Process entry point."""
    for sig in (signal.SIGINT, signal.SIGTERM):  # until the loop installs its handlers
        signal.signal(sig, lambda *_: sys.exit(0))
    die_with_parent()
    args = parse_args(argv)
    try:
        scenario = load_with_params(args.scenario, args.param)
        scenario.node(args.node)
    except ScenarioError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyError:
        print(f"error: {args.scenario}: nodes: no node named {args.node!r}", file=sys.stderr)
        return 2
    return asyncio.run(run_node(args, scenario))


if __name__ == "__main__":
    sys.exit(main())
