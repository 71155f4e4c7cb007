"""The launcher: an embedded Zenoh router plus one OS process per node.

`run_fleet` opens a Zenoh session in router mode on ``tcp/127.0.0.1:<free
port>`` (or joins ``--connect EP`` as a client), starts every node of the
scenario with `asyncio.create_subprocess_exec` (``python -m
runtime.fleet.node_main``; never fork after a session, never `multiprocessing`),
prefixes every output line with ``[node]``, and supervises the processes: a
node that dies is reported with its exit code and last lines, restarted if the
scenario says ``respawn: true``, and otherwise ends the run as failed.

The run ends at the timeout, when a node publishes a `String` on
``/twinfleet/shutdown``, when every node has exited, when a node fails, or on
SIGINT/SIGTERM. Fleet time 0: once every node's liveliness token is seen, the
launcher declares the fleet's epoch as a token (`keys.epoch_key`); the
nodes (``--fleet-epoch``) wait for it and run `@on_start` at time 0, as the
checker does, a respawned one (``--restarted``) at its restart time.
Shutdown escalates SIGINT → SIGTERM → SIGKILL per process;
children also get PR_SET_PDEATHSIG, so none outlives a SIGKILLed launcher.

With ``run_record=PATH`` the run is also written as JSON lines, one flushed
line per event (start, node exits and respawns, end reason, node statistics,
summary): see `runtime.fleet.run_record`.

With ``record_events=PATH`` every node logs each event it dispatches
(`runtime.host.replay_gate.EventLog`) into ``PATH.parts/<node>.jsonl``, flushed per line;
after shutdown the launcher merges the parts into PATH: a ``fleet`` header
line, the node headers, then every event in dispatch-time order (each
node's own order kept, a respawn as a ``crash`` record: `eventlog.with_restarts`),
and removes the parts. ``node_args`` are appended to
every node's command line (``--gate`` for a live replay), and a ``driver``
coroutine, started once the nodes are, ends the run with the reason it returns.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import heapq
import importlib
import json
import os
import shutil
import signal
import socket
import sys
import tempfile
import threading
import time
from collections import deque
from collections.abc import Awaitable, Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO, final

import msgpack
import yaml

from twinfleet.runtime.contract.kinds import Status
from twinfleet.runtime.contract.messages import DecodeError, decode
from twinfleet.runtime.contract.node import QOS_DEFAULT
from twinfleet.runtime.core.eventlog import EVENTS_FORMAT, with_restarts
from twinfleet.runtime.core.guard import Rejected, check_message, payload_limit
from twinfleet.runtime.core.state_report import decode_report
from twinfleet.runtime.core.statistics import NodeStatistics, Rejection, StatisticsError
from twinfleet.runtime.fleet import fleetauth, registry
from twinfleet.runtime.fleet.connection import EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK
from twinfleet.runtime.fleet.live_verdict import RESULT_WORDS, LiveMonitor, RunEnd, Verdict
from twinfleet.runtime.fleet.node_main import LIMIT_ENV, PARENT_ENV, read_statistics
from twinfleet.runtime.fleet.run_record import RunRecord, versions
from twinfleet.runtime.host.introspect import fleet_description, param_arguments
from twinfleet.runtime.host.keys import (
    KeyKind,
    epoch_key,
    fleet_key,
    kind_expr,
    parse_node_key,
    topic_key,
)
from twinfleet.runtime.host.zenoh_transport import ZenohTransport, zenoh_config
from twinfleet.runtime.scenario.scenario_file import write_scenario
from twinfleet.runtime.scenario.spec import NodeConfig, Scenario

SHUTDOWN_TOPIC = "/twinfleet/shutdown"
#: `-P`: the working directory does not go first on a node process's `sys.path`, so user
#: modules resolve exactly as `twinfleet check` resolves them (`scenario.spec.user_import_path`).
NODE_PROCESS_FLAGS = ("-P",)
_LAST_LINES = 15
_GRACE_S = (3.0, 2.0)  # after SIGINT, after SIGTERM; then SIGKILL
_RESPAWN_DELAY_S = 0.5
_REPORT_GRACE_S = 0.5  # wall seconds between the report's "finished" and the end of the run
_STATS_TIMEOUT_S = 2.0  # for the nodes' final statistics (the live verdict reads them)


class FleetConflict(ValueError):
    """Nodes of the fleet are already alive on the router; the text names them."""


@dataclass(frozen=True)
class FleetResult:
    """How a run ended.

    Attributes:
        fleet: the fleet name (Zenoh key prefix `twinfleet/<fleet>`).
        endpoint: the router endpoint the nodes connected to.
        reason: why the run ended ("timeout after 5 s", "shutdown requested by ...", ...).
        exit_codes: last exit code of every node (negative: killed by that signal).
        failed: nodes that failed (non-zero exit, or had to be killed).
        restarts: respawn count per node.
        last_messages: last message seen on each `live.summary_topics` topic.
        duration_s: wall time of the run.
        report: the scenario's run report (`live.report`), if any.
        verdict: the live verdict on the scenario's properties (None: not monitored).
        handler_failures: handler failures per node, from the state reports.
    """

    fleet: str
    endpoint: str
    reason: str
    exit_codes: Mapping[str, int | None]
    failed: tuple[str, ...]
    restarts: Mapping[str, int] = field(default_factory=dict)
    last_messages: Mapping[str, Any] = field(default_factory=dict)
    duration_s: float = 0.0
    report: Any = None
    verdict: Verdict | None = None
    handler_failures: Mapping[str, int] = field(default_factory=dict)
    state_reports: int = 0  # state reports the monitor received

    @property
    def ok(self) -> bool:
        """True when no node failed."""
        return not self.failed

    @property
    def passed(self) -> bool:
        """True when no node failed and the live verdict (`runtime.fleet.live_verdict`) holds;
        without one (``monitor=False``), when the scenario's report (if any) says so."""
        if self.verdict is not None:
            return self.ok and self.verdict.status is Status.HOLDS
        return self.ok and (self.report is None or self.report.passed())

    @property
    def interrupted(self) -> bool:
        """True when the run ended on SIGINT or SIGTERM (Ctrl-C, a stop request)."""
        return _interrupted(self.reason)

    @property
    def exit_code(self) -> int:
        """0 passed, 1 violated or a node failed, 2 a property raised, 3 inconclusive,
        130 interrupted (`runtime.fleet.connection`)."""
        if self.verdict is not None:
            return self.verdict.exit_code
        if self.interrupted:
            return EXIT_INTERRUPTED
        return EXIT_OK if self.passed else EXIT_FAILED


def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@final
class _NodeProcess:
    """One supervised node process and its output pump."""

    def __init__(self, cfg: NodeConfig, argv: list[str], out: TextIO,
                 secrets: Mapping[str, str] | None = None) -> None:
        self.cfg, self.argv, self.out = cfg, argv, out
        self.secrets = dict(secrets or {})
        self.proc: asyncio.subprocess.Process | None = None
        self.last_lines: deque[str] = deque(maxlen=_LAST_LINES)
        self.restarts = 0
        self.exit_code: int | None = None
        self._pump: asyncio.Task[None] | None = None

    async def start(self) -> None:
        env = dict(os.environ)
        env["PYTHONUNBUFFERED"] = "1"
        env[PARENT_ENV] = str(os.getpid())
        env.update(self.secrets)  # the environment: other users cannot read it, unlike argv
        self.exit_code = None
        self.proc = await asyncio.create_subprocess_exec(
            *self.argv, stdin=asyncio.subprocess.DEVNULL, stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.STDOUT, env=env, start_new_session=True)
        self._pump = asyncio.create_task(self._copy_output(self.proc))

    async def _copy_output(self, proc: asyncio.subprocess.Process) -> None:
        assert proc.stdout is not None
        async for raw in proc.stdout:
            line = raw.decode(errors="replace").rstrip("\n")
            self.last_lines.append(line)
            _emit(self.out, f"[{self.cfg.name}] {line}")

    async def wait(self) -> int:
        """Wait for the process to exit and its output to be copied; return the exit code."""
        assert self.proc is not None
        code = await self.proc.wait()
        if self._pump is not None:
            await asyncio.wait([self._pump], timeout=2.0)
        self.exit_code = code
        return code

    def running(self) -> bool:
        return self.proc is not None and self.proc.returncode is None

    def signal(self, sig: int) -> None:
        if self.running():
            assert self.proc is not None
            with contextlib.suppress(ProcessLookupError):
                self.proc.send_signal(sig)


def _emit(out: TextIO, line: str) -> None:
    out.write(line + "\n")
    out.flush()


@final
class Fleet:
    """A running fleet; `run_fleet` is the usual way to use it."""

    def __init__(self, scenario: Scenario, *, time_scale: float, seed: int,
                 connect: str | None, listen: str | None, out: TextIO,
                 record: RunRecord | None = None, node_args: Sequence[str] = (),
                 events_dir: Path | None = None, keep_scenario_beside: str | None = None,
                 monitor: bool = True, auth: fleetauth.MonitorAuth | None = None) -> None:
        self.time_scale, self.seed, self.out = time_scale, seed, out
        self.record = record
        self.node_args, self.events_dir = tuple(node_args), events_dir
        self.connect = connect
        self.endpoint = connect or listen or f"tcp/127.0.0.1:{free_port()}"
        self.creds = fleetauth.FleetCredentials.fresh()
        # Joining a router (--connect): the fleet there may span machines; its key and
        # operator login (this machine's registry, or --credentials FILE) make us a member.
        joined = (auth if auth is not None else fleetauth.registry_auth(connect)) if connect \
            else None
        if joined is not None and joined.key is not None:
            self.creds = dataclasses.replace(self.creds, key=joined.key)
        self.limit = scenario_payload_limit(scenario)
        self._auth_dir: Path | None = None
        self._login = joined.login(write=True) if joined is not None else None
        self.transport: ZenohTransport | None = None
        self.epoch_ns = time.time_ns()
        #: nodes whose liveliness token has not appeared yet; `all_alive` is set when none is
        #: left (the epoch is declared then: `_watch_for_epoch`)
        self.unseen = {cfg.name for cfg in scenario.nodes}
        self.all_alive = asyncio.Event()
        self.processes: dict[str, _NodeProcess] = {}
        self.last_messages: dict[str, Any] = {}
        self.ended: asyncio.Future[str] | None = None
        self.shutting_down = False
        self.failed: list[str] = []
        self.report = load_report(scenario)
        self.monitor = LiveMonitor(scenario, time_scale=time_scale) if monitor else None
        self.statistics: dict[str, NodeStatistics] = {}
        self.unreadable_statistics: dict[str, str] = {}  # node -> why `from_dict` refused them
        self.invalid = 0  # report samples refused by `guard.check_message`
        self._finishing = False
        self.scenario, self._private_dir = launchable(scenario, keep_scenario_beside)

    def log(self, text: str) -> None:
        """A launcher line on the output."""
        _emit(self.out, f"[launcher] {text}")

    def end(self, reason: str) -> None:
        """End the run (first reason wins)."""
        if self.ended is not None and not self.ended.done():
            self.ended.set_result(reason)

    async def open(self) -> None:
        """Open the router (or client) session and the launcher's subscriptions."""
        self.ended = asyncio.get_running_loop().create_future()
        if self.connect:  # someone else's router: its access control is theirs
            conf = zenoh_config(connect=[self.connect], mode="client",
                                settings=self._login.settings() if self._login else None)
        else:
            self._auth_dir = fleetauth.private_dir()
            settings = fleetauth.router_settings(self.creds, self._auth_dir)
            settings["transport/link/rx/max_message_size"] = self.limit + 1024
            conf = zenoh_config(listen=[self.endpoint], mode="router", settings=settings)
        self.transport = ZenohTransport(conf, key=self.creds.key, limit=self.limit)
        await self.transport.open()
        fleet = self.scenario.fleet
        self._describe(fleet)
        self.transport.subscribe(topic_key(fleet, SHUTDOWN_TOPIC), self._on_shutdown, QOS_DEFAULT)
        for topic in self.scenario.live.summary_topics:
            self.transport.subscribe(topic_key(fleet, topic), self._summary(topic), QOS_DEFAULT)
        for topic in self.report.topics() if self.report is not None else ():
            self.transport.subscribe(topic_key(fleet, topic), self._reported(topic), QOS_DEFAULT)
        if self.monitor is not None:
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
        assert self.monitor is not None
        try:
            report = decode_report(parse_node_key(key, KeyKind.STATE).node, payload)
        except ValueError as exc:
            self.log(f"ignored a malformed state report on {key}: {exc}")
            return
        self.monitor.on_report(report)

    def refusals(self) -> dict[Rejection, int]:
        """What the launcher's own subscriptions (report, shutdown) refused, by reason."""
        refused = self.transport.statistics().refused if self.transport is not None else {}
        return {Rejection.FORGED: refused.get(Rejection.FORGED, 0),
                Rejection.OVERSIZE: refused.get(Rejection.OVERSIZE, 0),
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
        return {**env, LIMIT_ENV: str(self.limit)}

    def _on_shutdown(self, _key: str, payload: bytes) -> None:
        try:
            env = decode(payload)
            text = getattr(env.msg, "data", str(env.msg))
            self.end(f"shutdown requested by {env.sender or '?'}: {text}")
        except DecodeError:
            self.end("shutdown requested (undecodable reason)")

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
                    _REPORT_GRACE_S, self.end, "the run report says every robot is done")
        return deliver

    def _argv(self, cfg: NodeConfig) -> list[str]:
        argv = [sys.executable, *NODE_PROCESS_FLAGS, "-m", "twinfleet.runtime.fleet.node_main", "--scenario", str(self.scenario.path),
                "--node", cfg.name, "--connect", self.endpoint, "--epoch-ns", str(self.epoch_ns),
                "--time-scale", repr(self.time_scale), "--seed", str(self.seed),
                "--fleet-epoch", *self.node_args]
        if self.monitor is not None:
            states = cfg.name in self.monitor.reads()
            argv += ["--monitor", "states" if states else "failures",
                     "--stall-ms", str(self.monitor.stall_ms)]
        if self.events_dir is not None:
            argv += ["--record-events", str(self.events_dir / f"{cfg.name}.jsonl")]
        return argv

    async def start_nodes(self) -> list[asyncio.Task[None]]:
        """Start every node process and one supervisor task per node; once every node is
        alive, declare the fleet's epoch (time 0) for them (`epoch_key`)."""
        self._watch_for_epoch()
        tasks = []
        for cfg in self.scenario.nodes:
            proc = _NodeProcess(cfg, self._argv(cfg), self.out, self.node_secrets())
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

    async def _supervise(self, proc: _NodeProcess) -> None:
        while True:
            code = await proc.wait()
            if self.shutting_down:
                return
            self.log(f"node {proc.cfg.name} exited with code {code}; last lines:")
            for line in proc.last_lines:
                _emit(self.out, f"    {line}")
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
                self.end(f"node {proc.cfg.name} failed (exit code {code})")
            elif not any(p.running() for p in self.processes.values()):
                self.end("all nodes exited")
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
        for sig, grace in ((signal.SIGINT, _GRACE_S[0]), (signal.SIGTERM, _GRACE_S[1]),
                           (signal.SIGKILL, 5.0)):
            alive = [p for p in procs if p.running()]
            if not alive:
                break
            if sig != signal.SIGINT:
                self.log(f"sending {signal.Signals(sig).name} to "
                         + ", ".join(p.cfg.name for p in alive))
            for p in alive:
                p.signal(sig)
            await asyncio.wait([asyncio.ensure_future(p.wait()) for p in alive], timeout=grace)
        for p in procs:
            code = p.exit_code if p.exit_code is not None else (p.proc and p.proc.returncode)
            p.exit_code = code
            if code not in (0, None) and p.cfg.name not in self.failed:
                self.failed.append(p.cfg.name)
        if self.transport is not None:
            await self.transport.close()
        if self._private_dir is not None:
            shutil.rmtree(self._private_dir, ignore_errors=True)
        fleetauth.remove_dir(self._auth_dir)


def scenario_payload_limit(scenario: Scenario) -> int:
    """The per-topic payload limit of a fleet: `live.max_payload_bytes`, else sized to the
    scenario's map (the occupancy grid is the largest message: `guard.payload_limit`)."""
    configured = scenario.live.max_payload_bytes
    if configured is not None or scenario.map_path is None:
        return payload_limit(0, 0, configured)
    cells = 0
    with contextlib.suppress(OSError, ValueError, TypeError, AttributeError):
        doc = yaml.safe_load(scenario.map_path.read_text())
        image = scenario.map_path.parent / str(doc["image"])
        cells = image.stat().st_size  # a binary PGM: one byte per cell, plus its header
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


async def run_fleet(scenario: Scenario, *, time_scale: float | None = None,
                    timeout_s: float | None = None, seed: int | None = None,
                    connect: str | None = None, listen: str | None = None,
                    out: TextIO = sys.stdout, handle_signals: bool = True,
                    run_record: str | None = None, record_events: str | None = None,
                    node_args: Sequence[str] = (), params: Sequence[str] = (),
                    driver: Callable[[Fleet], Awaitable[str]] | None = None,
                    monitor: bool = True,
                    auth: fleetauth.MonitorAuth | None = None) -> FleetResult:
    """Run a fleet until timeout, shutdown request, failure or signal; return how it ended.

    Args:
        scenario: a validated scenario (`runtime.scenario.spec.load_scenario`, or
            `Scenario.build`: then written to a file for the node processes, see `launchable`).
        time_scale: fleet speed-up (default: scenario `live.time_scale`, else 1).
        timeout_s: wall seconds before the run ends (default: `live.timeout_s`, else none).
        seed: fleet seed (default: the scenario's).
        connect: join this Zenoh router instead of embedding one.
        listen: endpoint of the embedded router (default: tcp/127.0.0.1:<free port>).
        out: where the prefixed output lines go.
        handle_signals: end the run on SIGINT/SIGTERM (main thread only).
        run_record: write the run as JSON lines to this file (`runtime.fleet.run_record`).
        record_events: write every dispatched event to this file (module docstring).
        node_args: extra arguments for every node process (`runtime.fleet.node_main`).
        params: parameter overrides ``[NODE.]NAME=VALUE`` (`runtime.host.introspect`); the
            scenario must already be loaded with them (`introspect.load_with_params`).
        driver: a coroutine function run with the fleet once its nodes started; the run
            ends with the reason it returns (an exception it raises is re-raised).
        monitor: judge the scenario's properties live (`runtime.fleet.live_verdict`; the
            result's `verdict`); False: no state reports (the result follows exits and
            the report only).
        auth: with `connect`, the joined fleet's key and logins (default: this machine's
            fleet registry entry for that endpoint, if any).
    """
    live = scenario.live
    time_scale = float(time_scale if time_scale is not None else live.time_scale)
    timeout_s = timeout_s if timeout_s is not None else live.timeout_s
    seed = scenario.seed if seed is None else seed
    record = RunRecord(run_record) if run_record else None
    events_dir = _fresh_parts_dir(record_events) if record_events else None
    fleet = Fleet(scenario, time_scale=time_scale, seed=seed, connect=connect, listen=listen,
                  out=out, record=record, node_args=[*node_args, *param_arguments(params)],
                  events_dir=events_dir, keep_scenario_beside=record_events or run_record,
                  monitor=monitor, auth=auth)
    scenario = fleet.scenario  # loaded from a file node processes can read
    entry: Path | None = None
    driving: asyncio.Task[str] | None = None
    started = time.monotonic()
    loop = asyncio.get_running_loop()
    signals = _install_signals(loop, fleet) if handle_signals else []
    tasks: list[asyncio.Task[None]] = []
    reason = "launcher error"
    running: list[str] = []
    try:
        if record is not None:
            _record_start(record, fleet, seed=seed, time_scale=time_scale, timeout_s=timeout_s)
        await fleet.open()
        if connect:  # an embedded router is new: only a shared one can hold a twin fleet
            await refuse_twins(fleet)
        entry = _register(fleet, params)
        fleet.log(f"fleet {scenario.fleet!r} on {fleet.endpoint} "
                  f"(time scale {time_scale:g}, seed {seed}); monitor with: twinfleet node list --fleet "
                  f"{scenario.fleet}"
                  + ("" if entry else f" --connect {fleet.endpoint}"))
        tasks = await fleet.start_nodes()
        assert fleet.ended is not None
        if driver is not None:
            driving = asyncio.create_task(driver(fleet))
            driving.add_done_callback(lambda task: fleet.end(_driver_reason(task)))
        reason = await _until_end(fleet, timeout_s)
        running = [name for name, p in fleet.processes.items() if p.running()]
        await _final_statistics(fleet, record, reason)
    finally:
        if driving is not None and not driving.done():
            driving.cancel()
            await asyncio.wait([driving], timeout=5.0)
        registry.unregister(entry)
        await fleet.shutdown()
        for task in tasks:
            task.cancel()
        if events_dir is not None and record_events is not None:
            _merge_logged(events_dir, record_events, fleet)
        for sig in signals:
            loop.remove_signal_handler(sig)
        if record is not None and sys.exc_info()[0] is not None:
            record.write("end", reason=f"launcher error: {sys.exc_info()[1]!r}")
            record.close()
    result = _result(fleet, reason, running, time.monotonic() - started)
    if record is not None:
        _record_summary(record, result)
        record.close()
    if driving is not None and not driving.cancelled() and driving.exception() is not None:
        raise driving.exception()  # type: ignore[misc]
    return result


async def alive_names(fleet: Fleet, timeout_s: float = 1.0) -> list[str]:
    """Names of `fleet`'s nodes whose liveliness tokens the router holds now."""
    if fleet.transport is None or fleet.transport.session is None:
        return []
    key = kind_expr(fleet.scenario.fleet, KeyKind.NODE)
    session = fleet.transport.session

    def query() -> list[str]:
        return [parse_node_key(str(r.ok.key_expr), KeyKind.NODE).node
                for r in session.liveliness().get(key, timeout=timeout_s) if r.ok is not None]

    return sorted(set(await asyncio.to_thread(query)))


async def refuse_twins(fleet: Fleet) -> None:
    """Raise `FleetConflict` when nodes of `fleet`'s scenario already run in it (a
    second launch on the same router would merge both runs' traffic silently)."""
    wanted = {cfg.name for cfg in fleet.scenario.nodes}
    twins = [name for name in await alive_names(fleet) if name in wanted]
    if twins:
        raise FleetConflict(
            f"fleet {fleet.scenario.fleet!r} at {fleet.endpoint} already runs "
            f"{', '.join(twins)}: a second launch would merge with it; stop that run, or "
            "give this one another fleet name (the scenario's `fleet:`)")


def _record_start(record: RunRecord, fleet: Fleet, *, seed: int, time_scale: float,
                  timeout_s: float | None) -> None:
    scenario = fleet.scenario
    record.write("start", scenario=str(scenario.path), name=scenario.name, fleet=scenario.fleet,
                 seed=seed, time_scale=time_scale, timeout_s=timeout_s, endpoint=fleet.endpoint,
                 versions=versions(),
                 nodes=[{"name": c.name, "class": c.class_path, "respawn": c.respawn}
                        for c in scenario.nodes])


async def _until_end(fleet: Fleet, timeout_s: float | None) -> str:
    """Why the run ended: what `fleet.end` was told, or the timeout."""
    assert fleet.ended is not None
    try:
        reason = await asyncio.wait_for(asyncio.shield(fleet.ended), timeout_s)
    except TimeoutError:
        reason = f"timeout after {timeout_s:g} s"
    fleet.log(f"run ended: {reason}")
    return reason


async def _final_statistics(fleet: Fleet, record: RunRecord | None, reason: str) -> None:
    """Ask the nodes for their counters (the verdict and the run record read them) and say
    what the launcher's own subscriptions refused."""
    if record is not None or fleet.monitor is not None:
        fleet.statistics, fleet.unreadable_statistics = await fleet.node_statistics(
            _STATS_TIMEOUT_S)
    for node, why in fleet.unreadable_statistics.items():
        fleet.log(f"could not read the statistics of {node}: {why}")
    refused = {k: v for k, v in fleet.refusals().items() if v}
    if refused:
        fleet.log("refused samples on the report and shutdown topics: "
                  + ", ".join(f"{k} {v}" for k, v in refused.items()))
    if record is not None:
        record.write("end", reason=reason)
        record.write("node_stats", stats={n: s.to_dict() for n, s in fleet.statistics.items()})


def _merge_logged(parts: Path, path: str, fleet: Fleet) -> None:
    try:
        count = merge_events(parts, path, fleet)
        fleet.log(f"{count} events written to {path}; check them with: "
                  f"twinfleet validate {path} {fleet.scenario.path}")
    except OSError as exc:  # the parts stay; `validate` reads them too
        fleet.log(f"could not merge the event logs in {parts}: {exc}")


def _result(fleet: Fleet, reason: str, running: Sequence[str], duration_s: float) -> FleetResult:
    codes = {name: p.exit_code for name, p in fleet.processes.items()}
    monitor = fleet.monitor
    return FleetResult(fleet=fleet.scenario.fleet, endpoint=fleet.endpoint, reason=reason,
                       exit_codes=codes, failed=tuple(fleet.failed),
                       restarts={n: p.restarts for n, p in fleet.processes.items()},
                       last_messages=dict(fleet.last_messages), duration_s=duration_s,
                       report=fleet.report, verdict=_verdict(fleet, reason, running, codes),
                       handler_failures=dict(monitor.failures) if monitor else {},
                       state_reports=monitor.reports if monitor else 0)


def _verdict(fleet: Fleet, reason: str, running: Sequence[str],
             codes: Mapping[str, int | None]) -> Verdict | None:
    """The live verdict of the run (None without a monitor)."""
    if fleet.monitor is None:
        return None
    dropped = fleet.transport.statistics().overflow if fleet.transport is not None else 0
    end = RunEnd(reason, interrupted=_interrupted(reason),
                 failed={n: codes.get(n) for n in fleet.failed}, statistics=fleet.statistics,
                 running=tuple(running), dropped_reports=dropped,
                 unreadable=fleet.unreadable_statistics)
    return fleet.monitor.verdict(end)


def _register(fleet: Fleet, params: Sequence[str]) -> Path | None:
    """Enter the fleet in the per-user registry (`runtime.fleet.registry`) so that monitors find it;
    None (and a line saying why) when the registry cannot be written."""
    try:
        return registry.register(fleet.scenario.fleet, fleet.endpoint,
                                 scenario=str(fleet.scenario.path), params={"overrides": list(params)},
                                 extra=fleet.creds.registry_extra())
    except (OSError, registry.RegistryError) as exc:
        fleet.log(f"not registered for discovery ({exc}); monitors need --connect")
        return None


def _driver_reason(task: asyncio.Task[str]) -> str:
    if task.cancelled():
        return "driver cancelled"
    exc = task.exception()
    return f"driver failed: {exc!r}" if exc is not None else str(task.result())


def _fresh_parts_dir(path: str) -> Path:
    parts = Path(f"{path}.parts")
    if parts.exists():
        shutil.rmtree(parts)
    parts.mkdir(parents=True)
    return parts


def merge_events(parts: Path, path: str, fleet: Fleet) -> int:
    """Merge the per-node event logs in `parts` into `path` (module docstring); return how
    many events there are."""
    headers, streams, restarts = [], [], {}
    for cfg in fleet.scenario.nodes:
        part = parts / f"{cfg.name}.jsonl"
        lines = part.read_text().splitlines() if part.exists() else []
        records = []
        for line in lines:
            with contextlib.suppress(json.JSONDecodeError):  # a torn last line
                records.append(json.loads(line))
        headers += [r for r in records if r.get("kind") == "header"][:1]
        events, restarted = with_restarts(records)
        if restarted:
            restarts[cfg.name] = restarted
        streams.append(events)
    with open(path, "w", encoding="utf-8") as f:
        f.write(json.dumps({"format": EVENTS_FORMAT, "kind": "fleet",
                            "scenario": str(fleet.scenario.path), "fleet": fleet.scenario.fleet,
                            "seed": fleet.seed, "time_scale": fleet.time_scale,
                            "epoch_ns": fleet.epoch_ns, "node_args": list(fleet.node_args),
                            "nodes": [c.name for c in fleet.scenario.nodes],
                            "restarts": restarts}) + "\n")
        for record in [*headers, *heapq.merge(*streams, key=lambda r: r["t"])]:
            f.write(json.dumps(record, separators=(",", ":")) + "\n")
    shutil.rmtree(parts, ignore_errors=True)
    return sum(len(s) for s in streams)


def _record_summary(record: RunRecord, result: FleetResult) -> None:
    report = None
    if result.report is not None:
        report = {"passed": result.report.passed(), "text": result.report.render(),
                  "data": result.report}
    verdict = None
    if result.verdict is not None:
        v = result.verdict
        verdict = {"status": v.status, "summary": v.summary, "details": list(v.details),
                   "property": v.property_name, "exit_code": v.exit_code}
    record.write("summary", ok=result.ok, passed=result.passed, verdict=verdict,
                 reason=result.reason,
                 exit_codes=result.exit_codes, failed=result.failed, restarts=result.restarts,
                 duration_s=round(result.duration_s, 3), last_messages=result.last_messages,
                 report=report)


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


def _interrupted(reason: str) -> bool:
    """Whether a run's end `reason` is a signal `_install_signals` turned into an end."""
    return reason.startswith(("SIGINT", "SIGTERM"))


def _install_signals(loop: asyncio.AbstractEventLoop, fleet: Fleet) -> list[int]:
    if threading.current_thread() is not threading.main_thread():
        return []
    sigs = [signal.SIGINT, signal.SIGTERM]
    for sig in sigs:
        loop.add_signal_handler(sig, fleet.end, f"{signal.Signals(sig).name} received")
    return sigs


def format_result(result: FleetResult) -> list[str]:
    """Human-readable summary lines of a run."""
    lines = [f"run ended after {result.duration_s:.1f} s: {result.reason}"]
    for name, code in result.exit_codes.items():
        failures = result.handler_failures.get(name, 0)
        status = "FAILED" if name in result.failed else (
            f"FAILED: {failures} handler failures" if failures else "ok")
        extra = f", restarts {result.restarts[name]}" if result.restarts.get(name) else ""
        lines.append(f"  {name}: exit code {code} ({status}{extra})")
    for topic, msg in result.last_messages.items():
        lines.append(f"  last on {topic}: {msg}")
    if result.report is not None:
        lines += result.report.render().splitlines()
        if result.verdict is None:
            status = Status.HOLDS if result.passed else Status.VIOLATED
            lines.append(f"result: {RESULT_WORDS[status]}")
    if result.verdict is not None:
        lines += result.verdict.lines()
    return lines

