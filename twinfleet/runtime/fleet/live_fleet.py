"""A running fleet: its Zenoh session, its node processes and what it hears.

`Fleet` opens a Zenoh session in router mode on ``tcp/127.0.0.1:<free port>`` (or joins
``--connect EP`` as a client), subscribes to the shutdown topic, the scenario's summary and
report topics and (for the live verdict) the nodes' state reports, and starts one
`NodeProcess` per node. It supervises them: a node that dies is reported with its exit code
and last lines, restarted if the scenario says ``respawn: true``, and otherwise ends the run
as failed (`Fleet.end`; the first reason wins). `launcher.run_fleet` drives it.

Fleet time 0: once every node's liveliness token is seen, the fleet declares its epoch as
a token (`keys.epoch_key`); the nodes (``--fleet-epoch``) wait for it and run
`@on_start` at time 0, as the checker does, a respawned one (``--restarted``) at its
restart time.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import importlib
import shutil
import signal
import socket
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TextIO, final

import msgpack

from twinfleet.runtime.access import fleetauth
from twinfleet.runtime.contract.messages import DecodeError, decode
from twinfleet.runtime.contract.node import QOS_DEFAULT
from twinfleet.runtime.core.guard import Rejected, check_message, payload_limit
from twinfleet.runtime.core.state_report import decode_report
from twinfleet.runtime.core.statistics import NodeStatistics, Rejection, StatisticsError
from twinfleet.runtime.fleet.fleet_result import EndReason, RunEnding
from twinfleet.runtime.fleet.live_verdict import LiveJudge
from twinfleet.runtime.fleet.node_main import LIMIT_ENV, read_statistics
from twinfleet.runtime.fleet.node_process import NODE_PROCESS_FLAGS, NodeProcess, emit, stop_all
from twinfleet.runtime.fleet.run_record import RunRecord
from twinfleet.runtime.host import certs
from twinfleet.runtime.host.introspect import fleet_description
from twinfleet.runtime.host.keys import (
    KeyKind,
    epoch_key,
    fleet_key,
    kind_expr,
    parse_node_key,
    topic_key,
)
from twinfleet.runtime.host.zenoh_transport import ZenohTransport, zenoh_config
from twinfleet.runtime.scenario.files import largest_file_bytes
from twinfleet.runtime.scenario.scenario_file import write_scenario
from twinfleet.runtime.scenario.spec import NodeConfig, Scenario

SHUTDOWN_TOPIC = "/twinfleet/shutdown"
_RESPAWN_DELAY_S = 0.5
#: exit codes of a process ended by the launcher's own stop signals: not a failure of the node
_STOPPED = (-signal.SIGINT, -signal.SIGTERM, -signal.SIGKILL)
_REPORT_GRACE_S = 0.5  # wall seconds between the report's "finished" and the end of the run


def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@final
class Fleet:
    """A running fleet; `run_fleet` is the usual way to use it."""

    def __init__(self, scenario: Scenario, *, time_scale: float, seed: int,
                 connect: str | None, listen: str | None, out: TextIO,
                 record: RunRecord | None = None, node_args: Sequence[str] = (),
                 events_dir: Path | None = None, keep_scenario_beside: str | None = None,
                 judge: bool = True, auth: fleetauth.MonitorAuth | None = None,
                 bridge: bool = False, accept_recorded: bool = False,
                 until_settled: bool = False, until_violation: bool = False) -> None:
        self.time_scale, self.seed, self.out = time_scale, seed, out
        self.until_settled, self.until_violation = until_settled, until_violation
        self.accept_recorded = accept_recorded
        self.record = record
        self.node_args, self.events_dir = tuple(node_args), events_dir
        self.connect = connect
        self.listen = with_free_port(listen) if listen else f"tcp/127.0.0.1:{free_port()}"
        # where this machine's nodes and monitors reach the router (a wildcard listen address
        # is not one a certificate can name)
        self.endpoint = connect or local_endpoint(self.listen)
        # `bridge`: the fleet takes external input (a bridge key: `runtime.core.guard`)
        self.creds = fleetauth.FleetCredentials.fresh(bridge=bridge)
        #: the router's TLS certificate and key (an embedded router on tls/ or quic/)
        self.server_tls: certs.Pem | None = None
        self.tls_names: list[str] = []  # the names and addresses its certificate carries
        if not connect and fleetauth.secure(self.listen):
            authority = certs.fleet_authority(scenario.fleet)
            self.tls_names = certs.host_names(endpoint_host(self.listen))
            self.server_tls = certs.server_certificate(authority, self.tls_names)
            self.creds = dataclasses.replace(self.creds, tls_ca=authority.certificate)
        # Joining a router (--connect): the fleet there may span machines; its key and
        # operator login (this machine's registry, or --credentials FILE) make us a member.
        joined = (auth if auth is not None else fleetauth.registry_auth(connect)) if connect \
            else None
        if joined is not None and joined.key is not None:
            self.creds = dataclasses.replace(
                self.creds, key=joined.key,
                bridge=(joined.bridge or self.creds.bridge) if bridge else None)
        if joined is not None and joined.tls_ca is not None:
            self.creds = dataclasses.replace(self.creds, tls_ca=joined.tls_ca)
        self.limit = scenario_payload_limit(scenario)
        self._auth_dir: Path | None = None
        self._login = joined.login(write=True) if joined is not None else None
        self.transport: ZenohTransport | None = None
        self.epoch_ns = time.time_ns()
        #: nodes whose liveliness token has not appeared yet; `all_alive` is set when none is
        #: left (the epoch is declared then: `_watch_for_epoch`)
        self.unseen = {cfg.name for cfg in scenario.nodes}
        self.all_alive = asyncio.Event()
        self.processes: dict[str, NodeProcess] = {}
        self.last_messages: dict[str, Any] = {}
        self.ended: asyncio.Future[RunEnding] | None = None
        self.shutting_down = False
        self.failed: list[str] = []
        self.report = load_report(scenario)
        self.judge = LiveJudge(scenario, time_scale=time_scale, say=self.log) if judge else None
        self.statistics: dict[str, NodeStatistics] = {}
        self.unreadable_statistics: dict[str, str] = {}  # node -> why `from_dict` refused them
        self.invalid = 0  # report samples refused by `guard.check_message`
        self.unmet: list[str] = []  # what a driver could not do: `RunEnd.unmet`
        self._finishing = False
        self.scenario, self._private_dir = launchable(scenario, keep_scenario_beside)

    def log(self, text: str) -> None:
        """A launcher line on the output."""
        emit(self.out, f"[launcher] {text}")

    def end(self, kind: EndReason, detail: str) -> None:
        """End the run (the first ending wins)."""
        self.end_as(RunEnding(kind, detail))

    def end_as(self, ending: RunEnding) -> None:
        """End the run as `ending` (the first ending wins)."""
        if self.ended is not None and not self.ended.done():
            self.ended.set_result(ending)

    async def open(self) -> None:
        """Open the router (or client) session and the launcher's subscriptions."""
        self.ended = asyncio.get_running_loop().create_future()
        if self.connect:  # someone else's router: its access control is theirs
            conf = zenoh_config(connect=[self.connect], mode="client",
                                settings={**(self._login.settings() if self._login else {}),
                                          **fleetauth.tls_settings(self.creds.tls_ca)})
        else:
            self._auth_dir = fleetauth.private_dir()
            settings = fleetauth.router_settings(self.creds, self._auth_dir)
            settings["transport/link/rx/max_message_size"] = self.limit + 1024
            if self.server_tls is not None:
                settings.update(fleetauth.router_tls_settings(self.server_tls.certificate,
                                                              self.server_tls.key))
            conf = zenoh_config(listen=[self.listen], mode="router", settings=settings)
        self.transport = ZenohTransport(conf, key=self.creds.key, limit=self.limit)
        await self.transport.open()
        fleet = self.scenario.fleet
        self._describe(fleet)
        self.transport.subscribe(topic_key(fleet, SHUTDOWN_TOPIC), self._on_shutdown, QOS_DEFAULT)
        for topic in self.scenario.live.summary_topics:
            self.transport.subscribe(topic_key(fleet, topic), self._summary(topic), QOS_DEFAULT)
        for topic in self.report.topics() if self.report is not None else ():
            self.transport.subscribe(topic_key(fleet, topic), self._reported(topic), QOS_DEFAULT)
        if self.judge is not None:
            self.transport.subscribe(kind_expr(fleet, KeyKind.STATE), self._on_state,
                                    QOS_DEFAULT)

    def _describe(self, fleet: str) -> None:
        """Serve the fleet's description (its scene, its latched topics) to viewers that find
        the fleet only over Zenoh (`runtime.host.keys.fleet_key`); served before any
        node starts, so a viewer woken by a node's first sample finds it."""
        assert self.transport is not None
        description = msgpack.packb(fleet_description(self.scenario), use_bin_type=True)
        self.transport.serve(fleet_key(fleet), lambda _request, respond: respond(description, ""))

    def _on_state(self, key: str, payload: bytes) -> None:
        assert self.judge is not None
        try:
            report = decode_report(parse_node_key(key, KeyKind.STATE).node, payload)
        except ValueError as exc:
            self.log(f"ignored a malformed state report on {key}: {exc}")
            return
        self.judge.on_report(report)
        if self.until_violation and self.judge.violations:
            self.end(EndReason.VIOLATION, f"stopped at the first violation "
                     f"({self.judge.violations[0][0]}, at t={self.judge.now} ms)")
        if self.until_settled and self.judge.settled():
            self.end(EndReason.SETTLED, "settled: every eventually property held (the last "
                     f"at t={max(self.judge.held_at.values())} ms)")

    def refusals(self) -> dict[Rejection, int]:
        """What the launcher's own subscriptions (report, shutdown) refused, by reason."""
        refused = self.transport.statistics().refused if self.transport is not None else {}
        return {**{reason: refused.get(reason, 0) for reason in (
            Rejection.FORGED, Rejection.OVERSIZE, Rejection.REPLAYED, Rejection.RECORDED)},
            Rejection.INVALID: self.invalid}

    def node_secrets(self) -> dict[str, str]:
        """The environment a node process gets: fleet key, login (embedded router), limit."""
        env = self.creds.node_env()
        if self.connect:  # a router we did not start: its login, if this machine knows it
            env.pop(fleetauth.ENV_USER)
            env.pop(fleetauth.ENV_PASSWORD)
            if self._login is not None:
                env.update({fleetauth.ENV_USER: self._login.user,
                            fleetauth.ENV_PASSWORD: self._login.password})
        if self.accept_recorded:
            env[fleetauth.ENV_ACCEPT_RECORDED] = "1"
        return {**env, LIMIT_ENV: str(self.limit)}

    def _on_shutdown(self, _key: str, payload: bytes) -> None:
        try:
            env = decode(payload)
            text = getattr(env.msg, "data", str(env.msg))
            self.end(EndReason.SHUTDOWN, f"shutdown requested by {env.sender or '?'}: {text}")
        except DecodeError:
            self.end(EndReason.SHUTDOWN, "shutdown requested (undecodable reason)")

    def _summary(self, topic: str) -> Any:
        def deliver(_key: str, payload: bytes) -> None:
            try:
                self.last_messages[topic] = decode(payload).msg
            except DecodeError:
                with contextlib.suppress(Exception):
                    self.last_messages[topic] = msgpack.unpackb(payload, raw=False)
        return deliver

    def _reported(self, topic: str) -> Any:
        def deliver(_key: str, payload: bytes) -> None:
            try:
                msg = decode(payload).msg
                check_message(msg)  # NaN cells or a string arrival time never reach the verdict
            except Rejected:
                self.invalid += 1
            except DecodeError:
                pass
            else:
                self.report.on_message(topic, msg)
            finished = getattr(self.report, "finished", None)
            if finished is not None and finished() and not self._finishing:
                # A grace period: messages already in flight from other nodes (a collision
                # found on the last pose) still reach the report.
                self._finishing = True
                asyncio.get_running_loop().call_later(
                    _REPORT_GRACE_S, self.end, EndReason.REPORT_FINISHED,
                    "the run report says the run is finished")
        return deliver

    def _argv(self, cfg: NodeConfig) -> list[str]:
        argv = [sys.executable, *NODE_PROCESS_FLAGS, "-m", "twinfleet.runtime.fleet.node_main", "--scenario", str(self.scenario.path),
                "--node", cfg.name, "--connect", self.endpoint, "--epoch-ns", str(self.epoch_ns),
                "--time-scale", repr(self.time_scale), "--seed", str(self.seed),
                "--fleet-epoch", *self.node_args]
        if self.judge is not None:
            states = cfg.name in self.judge.reads()
            argv += ["--report", "states" if states else "failures",
                     "--stall-ms", str(self.judge.stall_ms)]
        if self.events_dir is not None:
            argv += ["--record-events", str(self.events_dir / f"{cfg.name}.jsonl")]
        return argv

    async def start_nodes(self) -> list[asyncio.Task[None]]:
        """Start every node process and one supervisor task per node; once every node is
        alive, declare the fleet's epoch (time 0) for them (`epoch_key`)."""
        self._watch_for_epoch()
        tasks = []
        for cfg in self.scenario.nodes:
            proc = NodeProcess(cfg, self._argv(cfg), self.out, self.node_secrets())
            self.processes[cfg.name] = proc
            await proc.start()
            tasks.append(asyncio.create_task(self._supervise(proc)))
        return tasks

    def _watch_for_epoch(self) -> None:
        """Declare the epoch token when the last node's token appears: the nodes wait for
        it, so every `@on_start` runs at fleet time 0 on one shared clock."""
        assert self.transport is not None
        fleet, unseen, transport = self.scenario.fleet, self.unseen, self.transport

        def on_node(key: str, alive: bool) -> None:
            if alive and unseen:
                unseen.discard(parse_node_key(key, KeyKind.NODE).node)
                if not unseen:
                    self.epoch_ns = time.time_ns()
                    transport.announce(epoch_key(fleet, self.epoch_ns))
                    self.all_alive.set()

        transport.watch(kind_expr(fleet, KeyKind.NODE), on_node)

    async def _supervise(self, proc: NodeProcess) -> None:
        while True:
            code = await proc.wait()
            if self.shutting_down:
                return
            self.log(f"node {proc.cfg.name} exited with code {code}; last lines:")
            for line in proc.last_lines:
                emit(self.out, f"    {line}")
            if self.record is not None:
                self.record.write("node_exit", node=proc.cfg.name, code=code,
                                  last_lines=list(proc.last_lines))
            if proc.cfg.respawn:
                proc.restarts += 1
                self.log(f"respawning {proc.cfg.name} (restart {proc.restarts})")
                if self.record is not None:
                    self.record.write("respawn", node=proc.cfg.name, restart=proc.restarts)
                await asyncio.sleep(_RESPAWN_DELAY_S)
                if self.shutting_down:
                    return
                if "--restarted" not in proc.argv:
                    proc.argv.append("--restarted")
                await proc.start()
                continue
            if code != 0:
                self.failed.append(proc.cfg.name)
                self.end_as(RunEnding.node_exit(proc.cfg.name, code))
            elif not any(p.running() for p in self.processes.values()):
                self.end(EndReason.ALL_EXITED, "all nodes exited")
            return

    async def node_statistics(self, timeout_s: float = 0.5
                              ) -> tuple[dict[str, NodeStatistics], dict[str, str]]:
        """Each running node's `NodeStatistics`, read from its statistics queryable, and
        why the nodes whose answers could not be read were refused (node -> reason)."""
        if self.transport is None or self.transport.session is None:
            return {}, {}
        key = kind_expr(self.scenario.fleet, KeyKind.STATS)

        def query() -> tuple[dict[str, NodeStatistics], dict[str, str]]:
            found: dict[str, NodeStatistics] = {}
            unreadable: dict[str, str] = {}
            for reply in self.transport.session.get(key, timeout=timeout_s):  # type: ignore[union-attr]
                if reply.ok is not None:
                    try:
                        node = parse_node_key(str(reply.ok.key_expr), KeyKind.STATS).node
                    except ValueError:  # InvalidKey: not a node's statistics key
                        continue
                    try:
                        found[node] = read_statistics(reply.ok.payload.to_bytes())
                    except StatisticsError as exc:
                        unreadable[node] = str(exc)
            return found, unreadable

        return await asyncio.to_thread(query)

    async def shutdown(self) -> None:
        """Stop every process: SIGINT, then SIGTERM, then SIGKILL; close the session."""
        self.shutting_down = True
        procs = list(self.processes.values())
        await stop_all(procs, self.log)
        for p in procs:
            if p.final_code() not in (0, None, *_STOPPED) and p.cfg.name not in self.failed:
                self.failed.append(p.cfg.name)
        if self.transport is not None:
            await self.transport.close()
        if self._private_dir is not None:
            shutil.rmtree(self._private_dir, ignore_errors=True)
        fleetauth.remove_dir(self._auth_dir)


def endpoint_host(endpoint: str) -> str:
    """The host part of a Zenoh endpoint (``tls/10.0.0.1:7447`` → ``10.0.0.1``)."""
    address = endpoint.split("#", 1)[0].partition("/")[2]
    return address.rsplit(":", 1)[0]


def with_free_port(endpoint: str) -> str:
    """`endpoint` with port 0 replaced by a port of its host that was free a moment ago:
    the router listens there, and the nodes, monitors and registry are told that port (a
    router left to pick its own would listen where nobody is told)."""
    address, sep, options = endpoint.partition("#")
    head, _, port = address.rpartition(":")
    if port != "0":
        return endpoint
    host = endpoint_host(endpoint).strip("[]")
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family) as s:
        s.bind((host, 0))
        return f"{head}:{s.getsockname()[1]}{sep}{options}"


def local_endpoint(listen: str) -> str:
    """The endpoint a process on this machine connects to for a router listening on `listen`:
    the same, but for a wildcard address, which becomes the loopback one."""
    host = endpoint_host(listen)
    wildcard = {"0.0.0.0": "127.0.0.1", "[::]": "[::1]"}.get(host)
    return listen.replace(host, wildcard, 1) if wildcard else listen


def scenario_payload_limit(scenario: Scenario) -> int:
    """The per-topic payload limit of a fleet: `live.max_payload_bytes`, else sized to the
    largest file its nodes read (a grid read from one is the largest message a node sends
    whole: `guard.payload_limit`, one byte per cell)."""
    configured = scenario.live.max_payload_bytes
    cells = largest_file_bytes(scenario)
    if configured is not None or not cells:
        return payload_limit(0, 0, configured)
    return payload_limit(cells, 1)


def launchable(scenario: Scenario, beside: str | None) -> tuple[Scenario, Path | None]:
    """`scenario` as node processes can load it: itself when it has a file; else (built in
    Python) written to ``<beside>.scenario.yaml`` next to a record the caller keeps, or to a
    temporary directory, returned for removal (`runtime.scenario.scenario_file`)."""
    if scenario.path is not None:
        return scenario, None
    if beside is not None:
        return write_scenario(scenario, f"{beside}.scenario.yaml"), None
    private = Path(tempfile.mkdtemp(prefix="twinfleet-scenario-"))
    try:
        return write_scenario(scenario, private / f"{scenario.name}.yaml"), private
    except BaseException:
        shutil.rmtree(private, ignore_errors=True)
        raise


def load_report(scenario: Scenario) -> Any:
    """The run report named by the scenario's `live.report` ("module:factory"), or None.

    The factory takes the scenario and returns an object with `topics()`,
    `on_message(topic, msg)`, `passed()` and `render()`, and optionally
    `finished()` (True ends the run); the launcher feeds it every message on
    those topics (e.g. `nodes.report:report_for`).
    """
    path = scenario.live.report
    if not path:
        return None
    module, _, attr = path.partition(":")
    return getattr(importlib.import_module(module), attr)(scenario)
