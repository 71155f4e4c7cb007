"""The launcher: an embedded Zenoh router plus one OS process per node.

`run_fleet` runs a scenario as a fleet (`live_fleet.Fleet`: the router session, one
`node_process.NodeProcess` per node, their supervision) and returns how the run ended
(`fleet_result.FleetResult`). The run ends at the timeout, when a node publishes a `String`
on ``/twinfleet/shutdown``, when every node has exited, when a node fails, or on
SIGINT/SIGTERM. Shutdown escalates SIGINT → SIGTERM → SIGKILL per process
(`node_process.stop_all`).

With ``run_record=PATH`` the run is also written as JSON lines, one flushed line per event
(start, node exits and respawns, end reason, node statistics, summary): see
`runtime.fleet.run_record`. With ``record_events=PATH`` every node logs the events it
dispatches, merged into PATH after shutdown (`runtime.fleet.event_merge`). ``node_args``
are appended to every node's command line (``--gate`` for a live replay), and a ``driver``
coroutine, started once the nodes are, ends the run with the reason it returns.

The names callers of `run_fleet` need are importable from here, wherever they are defined
(`__all__`).
"""

from __future__ import annotations

import asyncio
import signal
import sys
import threading
import time
from collections.abc import Awaitable, Callable, Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any, TextIO, final

from twinfleet.runtime.access import registry
from twinfleet.runtime.fleet.event_merge import fresh_parts_dir, merge_logged
from twinfleet.runtime.fleet.fleet_result import (
    EndReason,
    FleetResult,
    RunEnding,
    format_result,
    record_summary,
    signal_exit_code,
)
from twinfleet.runtime.fleet.launch_options import STARTUP_S, LaunchOptions
from twinfleet.runtime.fleet.live_fleet import SHUTDOWN_TOPIC, Fleet, endpoint_host, free_port
from twinfleet.runtime.fleet.live_verdict import RunEnd, Verdict
from twinfleet.runtime.fleet.run_record import RunRecord, versions
from twinfleet.runtime.host.introspect import param_arguments
from twinfleet.runtime.host.keys import KeyKind, kind_expr, parse_node_key
from twinfleet.runtime.scenario.spec import Scenario

__all__ = [
    "SHUTDOWN_TOPIC",
    "Fleet",
    "FleetConflict",
    "FleetResult",
    "LaunchOptions",
    "STARTUP_S",
    "alive_names",
    "format_result",
    "free_port",
    "refuse_twins",
    "run_fleet",
]

_STATS_TIMEOUT_S = 2.0  # for the nodes' final statistics (the live verdict reads them)
_DRIVER_STOP_S = 5.0  # for a driver still running at the end to finish its cancellation


class FleetConflict(ValueError):
    """Nodes of the fleet are already alive on the router; the text names them."""


async def run_fleet(scenario: Scenario, options: LaunchOptions | None = None, *,
                    out: TextIO = sys.stdout,
                    driver: Callable[[Fleet], Awaitable[str]] | None = None) -> FleetResult:
    """Run a fleet until timeout, shutdown request, failure or signal; return how it ended.

    Args:
        scenario: a validated scenario (`load_scenario`, or `Scenario.build`: then written
            to a file for the node processes, `live_fleet.launchable`).
        options: how to launch it (`LaunchOptions`; None, and None fields: the scenario's).
        out: where the launcher's and the nodes' output goes.
        driver: a coroutine function run with the fleet once its nodes started; the run
            ends with the reason it returns (an exception it raises is re-raised).
    """
    o, live = options or LaunchOptions(), scenario.live
    time_scale = float(o.time_scale if o.time_scale is not None else live.time_scale)
    record = RunRecord(o.run_record) if o.run_record else None
    fleet = Fleet(scenario, time_scale=time_scale,
                  seed=scenario.seed if o.seed is None else o.seed, connect=o.connect,
                  listen=o.listen, out=out, record=record,
                  node_args=[*o.node_args, *param_arguments(o.params)],
                  events_dir=fresh_parts_dir(o.record_events) if o.record_events else None,
                  keep_scenario_beside=o.record_events or o.run_record, judge=o.judge,
                  auth=o.auth, bridge=o.bridge, accept_recorded=o.accept_recorded,
                  **_stops(live.stop, o.until_settled, o.until_violation))
    started = time.monotonic()
    async with _Launch(fleet, o.record_events, o.handle_signals) as launch:
        limit = wall_limit(live.wall_timeout_s, live.horizon_s, time_scale) \
            if o.timeout_s is None else wall_limit(o.timeout_s, None, time_scale)
        ending, running = await launch.until_end((o.startup_s, *limit), o.params, driver)
    result = _result(fleet, ending, running, time.monotonic() - started)
    if record is not None:
        record_summary(record, result)
        record.close()
    launch.raise_driver_failure()
    return result


def _stops(stop: str, until_settled: bool | None,
           until_violation: bool | None) -> dict[str, bool]:
    """The fleet's stop conditions: those given, else the scenario's ``live.stop``."""
    return {"until_settled": stop == "settled" if until_settled is None else until_settled,
            "until_violation": stop == "violation" if until_violation is None
            else until_violation}


def wall_limit(wall_timeout_s: float | None, horizon_s: float | None,
               time_scale: float) -> tuple[float | None, str]:
    """Wall seconds a run lasts from its epoch — the wall timeout, or the fleet-time horizon
    at this time scale if that comes first (None: no limit) — and the end reason then."""
    horizon = None if horizon_s is None else horizon_s / time_scale
    if horizon is not None and (wall_timeout_s is None or horizon < wall_timeout_s):
        return horizon, (f"the fleet-time horizon of {horizon_s:g} s "
                         f"({horizon:g} s of wall time at time scale {time_scale:g})")
    if wall_timeout_s is None:
        return None, "no limit"
    return wall_timeout_s, f"timeout after {wall_timeout_s:g} s"


@final
class _Launch:
    """One run of `run_fleet` from opening the fleet to its shutdown: what it started, so
    that leaving it (also on an error or a cancellation) stops exactly that."""

    def __init__(self, fleet: Fleet, record_events: str | None, handle_signals: bool) -> None:
        self.fleet, self.record_events = fleet, record_events
        self.loop = asyncio.get_running_loop()
        self.signals = _install_signals(self.loop, fleet) if handle_signals else []
        self.entry: Path | None = None  # the fleet registry's entry
        self.driving: asyncio.Future[str] | None = None
        self.tasks: list[asyncio.Task[None]] = []  # one supervisor per node

    async def __aenter__(self) -> _Launch:
        return self

    async def until_end(self, limits: tuple[float, float | None, str], params: Sequence[str],
                        driver: Callable[[Fleet], Awaitable[str]] | None
                        ) -> tuple[RunEnding, list[str]]:
        """Open the fleet, register it, start its nodes (and the driver) and wait for the
        end (`limits`: start-up and timeout seconds, the reason of the timeout); return why the run ended and which
        nodes were still running then."""
        fleet = self.fleet
        if fleet.record is not None:
            _record_start(fleet.record, fleet, timeout_s=limits[1])
        await fleet.open()
        if fleet.connect:  # an embedded router is new: only a shared one can hold a twin fleet
            await refuse_twins(fleet)
        self.entry = _register(fleet, params)
        fleet.log(f"fleet {fleet.scenario.fleet!r} on {fleet.endpoint} "
                  f"(time scale {fleet.time_scale:g}, seed {fleet.seed}); monitor with: "
                  f"twinfleet node list --fleet {fleet.scenario.fleet}"
                  + ("" if self.entry else f" --connect {fleet.endpoint}"))
        self.tasks = await fleet.start_nodes()
        if driver is not None:
            self.driving = asyncio.ensure_future(driver(fleet))
            self.driving.add_done_callback(lambda task: fleet.end(EndReason.DRIVER,
                                                                  _driver_reason(task)))
        ending = await _until_end(fleet, *limits)
        running = [name for name, p in fleet.processes.items() if p.running()]
        await _final_statistics(fleet, fleet.record, ending)
        return ending, running

    async def __aexit__(self, _kind: type[BaseException] | None, error: BaseException | None,
                        _tb: TracebackType | None) -> None:
        """Stop the driver, leave the registry, stop the nodes, merge the event logs and
        give the signals back; after an error, end the run record with it."""
        if self.driving is not None and not self.driving.done():
            self.driving.cancel()
            await asyncio.wait([self.driving], timeout=_DRIVER_STOP_S)
        registry.unregister(self.entry)
        await self.fleet.shutdown()
        for task in self.tasks:
            task.cancel()
        if self.fleet.events_dir is not None and self.record_events is not None:
            merge_logged(self.fleet.events_dir, self.record_events, self.fleet)
        for sig in self.signals:
            self.loop.remove_signal_handler(sig)
        record = self.fleet.record
        if record is not None and error is not None:
            record.write("end", reason=f"launcher error: {error!r}")
            record.close()

    def raise_driver_failure(self) -> None:
        """Raise what the driver raised, if it did."""
        driving = self.driving
        if driving is not None and not driving.cancelled() and driving.exception() is not None:
            raise driving.exception()  # type: ignore[misc]


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


def _record_start(record: RunRecord, fleet: Fleet, *, timeout_s: float | None) -> None:
    """The run record's ``start`` line: the scenario, the settings and the versions."""
    scenario = fleet.scenario
    record.write("start", scenario=str(scenario.path), name=scenario.name, fleet=scenario.fleet,
                 seed=fleet.seed, time_scale=fleet.time_scale, timeout_s=timeout_s,
                 endpoint=fleet.endpoint,
                 versions=versions(),
                 nodes=[{"name": c.name, "class": c.class_path, "respawn": c.respawn}
                        for c in scenario.nodes])


async def _until_end(fleet: Fleet, startup_s: float, timeout_s: float | None,
                     timed_out: str) -> RunEnding:
    """Why the run ended: what `fleet.end` was told, the start-up limit (some node not alive
    after `startup_s`), or the timeout, which counts from the epoch (every node alive): a
    loaded machine's slow imports are not the run's time."""
    assert fleet.ended is not None
    up: asyncio.Future[object] = asyncio.ensure_future(fleet.all_alive.wait())
    ended: asyncio.Future[RunEnding] = fleet.ended
    try:
        waited: list[asyncio.Future[Any]] = [ended, up]
        await asyncio.wait(waited, timeout=startup_s,
                           return_when=asyncio.FIRST_COMPLETED)
    finally:
        up.cancel()
    if not fleet.all_alive.is_set():
        fleet.end(EndReason.NOT_UP, f"the fleet was not up after {startup_s:g} s")
    try:
        ending = await asyncio.wait_for(asyncio.shield(fleet.ended), timeout_s)
    except TimeoutError:
        ending = RunEnding(EndReason.TIMEOUT, timed_out)
    fleet.log(f"run ended: {ending.detail}")
    return ending


async def _final_statistics(fleet: Fleet, record: RunRecord | None, ending: RunEnding) -> None:
    """Ask the nodes for their counters (the verdict and the run record read them) and say
    what the launcher's own subscriptions refused."""
    if record is not None or fleet.judge is not None:
        fleet.statistics, fleet.unreadable_statistics = await fleet.node_statistics(
            _STATS_TIMEOUT_S)
    for node, why in fleet.unreadable_statistics.items():
        fleet.log(f"could not read the statistics of {node}: {why}")
    refused = {k: v for k, v in fleet.refusals().items() if v}
    if refused:
        fleet.log("refused samples on the report and shutdown topics: "
                  + ", ".join(f"{k} {v}" for k, v in refused.items()))
    if record is not None:
        record.write("end", reason=ending.detail, end=ending.kind.value)
        record.write("node_stats", stats={n: s.to_dict() for n, s in fleet.statistics.items()})


def _result(fleet: Fleet, ending: RunEnding, running: Sequence[str],
            duration_s: float) -> FleetResult:
    """How the run ended, from the fleet after its shutdown."""
    codes = {name: p.exit_code for name, p in fleet.processes.items()}
    judge = fleet.judge
    return FleetResult(fleet=fleet.scenario.fleet, endpoint=fleet.endpoint,
                       reason=ending.detail, end=ending.kind, exit_codes=codes,
                       failed=tuple(fleet.failed),
                       restarts={n: p.restarts for n, p in fleet.processes.items()},
                       last_messages=dict(fleet.last_messages), duration_s=duration_s,
                       report=fleet.report, verdict=_verdict(fleet, ending, running, codes),
                       handler_failures=dict(judge.failures) if judge else {},
                       state_reports=judge.reports if judge else 0,
                       statistics=dict(fleet.statistics))


def _verdict(fleet: Fleet, ending: RunEnding, running: Sequence[str],
             codes: Mapping[str, int | None]) -> Verdict | None:
    """The live verdict of the run (None when the run is not judged)."""
    if fleet.judge is None:
        return None
    dropped = fleet.transport.statistics().overflow if fleet.transport is not None else 0
    end = RunEnd(ending.detail, interrupted=signal_exit_code(ending.kind) is not None,
                 failed={n: codes.get(n) for n in fleet.failed}, statistics=fleet.statistics,
                 running=tuple(running), dropped_reports=dropped,
                 not_up=() if fleet.all_alive.is_set() else tuple(sorted(fleet.unseen)),
                 unreadable=fleet.unreadable_statistics, unmet=tuple(fleet.unmet))
    return fleet.judge.verdict(end)


def _register(fleet: Fleet, params: Sequence[str]) -> Path | None:
    """Enter the fleet in the per-user registry (`runtime.access.registry`) so that monitors find it,
    with its router's TLS certificate and key beside it (owner-only); None (and a line saying
    why) when the registry cannot be written."""
    try:
        entry = registry.register(fleet.scenario.fleet, fleet.endpoint,
                                  scenario=str(fleet.scenario.path),
                                  params={"overrides": list(params)},
                                  extra=fleet.creds.registry_extra())
        if fleet.server_tls is not None:
            registry.write_beside(entry, "server.pem",
                                  fleet.server_tls.certificate + fleet.server_tls.key)
            fleet.log(f"TLS: certificates made for this launch; other hosts join with "
                      f"{_remote_hint(fleet)} --credentials FILE, FILE a copy of {entry}")
        return entry
    except (OSError, registry.RegistryError) as exc:
        fleet.log(f"not registered for discovery ({exc}); monitors need --connect")
        return None


def _remote_hint(fleet: Fleet) -> str:
    """``--connect EP`` for another host: the listen endpoint, or for a wildcard address
    the names its certificate carries."""
    host = endpoint_host(fleet.listen)
    if host not in ("0.0.0.0", "[::]"):
        return f"--connect {fleet.listen}"
    remote = [n for n in fleet.tls_names if n not in ("localhost", "127.0.0.1", "::1")]
    return (f"--connect {fleet.listen.replace(host, 'HOST', 1)} (HOST: "
            f"{', '.join(remote) or 'this machine'})")


def _driver_reason(task: asyncio.Task[str]) -> str:
    """The end reason a finished driver gives: what it returned, or how it failed."""
    if task.cancelled():
        return "driver cancelled"
    exc = task.exception()
    return f"driver failed: {exc!r}" if exc is not None else str(task.result())


def _install_signals(loop: asyncio.AbstractEventLoop, fleet: Fleet) -> list[int]:
    """End the run on SIGINT and SIGTERM (the main thread only: asyncio installs handlers
    there alone); return the signals to give back."""
    if threading.current_thread() is not threading.main_thread():
        return []
    sigs: list[int] = [signal.SIGINT, signal.SIGTERM]
    for sig in sigs:
        kind = EndReason.INTERRUPTED if sig == signal.SIGINT else EndReason.TERMINATED
        loop.add_signal_handler(sig, fleet.end, kind, f"{signal.Signals(sig).name} received")
    return sigs
