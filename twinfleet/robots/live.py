"""One live run of a scenario, with per-robot start and arrival times and an early stop.

`live_run` runs `runtime.fleet.launcher.run_fleet` in-process with the scenario's
run report replaced by a `TimedReport`: the usual `nodes.report.FleetReport`
plus each robot's first `planning` status time (its start: the launcher's
epoch is taken before the node processes exist, so fleet time 0 is not the
robots' time 0), its arrival time, "stuck" robots and the first collision.
As soon as the outcome is decided — every robot arrived or stuck, or (with
`stop_on_collision`) a collision — the run asks the fleet to stop by
publishing on ``/twinfleet/shutdown`` from a short-lived Zenoh client
session, so runs of the `rebeca` profile (whose robots never tell the map
server they are done) and failed runs do not wait for the timeout.

The report factory is named in the scenario (`live.report`) and called by the
launcher; it finds its hook through a context variable set by `live_run`.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import time
from collections.abc import Callable, Sequence
from contextvars import ContextVar
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO, final

import yaml

from twinfleet import QOS_DEFAULT, String
from twinfleet.nodes.mapfile import load_map
from twinfleet.nodes.msgs import Collision, RobotStatus
from twinfleet.nodes.report import FleetReport
from twinfleet.runtime.access.fleetauth import login_settings, registry_auth
from twinfleet.runtime.contract.messages import encode
from twinfleet.runtime.fleet.fleet_result import EndReason
from twinfleet.runtime.fleet.launcher import SHUTDOWN_TOPIC, LaunchOptions, free_port, run_fleet
from twinfleet.runtime.host.keys import topic_key
from twinfleet.runtime.host.zenoh_transport import ZenohTransport, zenoh_config
from twinfleet.runtime.scenario.files import with_absolute_files
from twinfleet.runtime.scenario.overrides import load_with_params, overrides_doc
from twinfleet.runtime.scenario.spec import Scenario, load_scenario

REPORT_FACTORY = "twinfleet.robots.live:timed_report_for"
_HOOK: ContextVar[Callable[[TimedReport], None] | None] = ContextVar("agreement_report_hook",
                                                                    default=None)


class TimedReport(FleetReport):
    """A `FleetReport` that also keeps start times, stuck robots and the first collision.

    Attributes:
        start_ms: per robot, fleet time of its first `planning` status (its `@on_start`).
        stuck: robots that gave up (status "stuck").
        first_collision_ms: fleet time of the first collision reported.
        on_decided: called once with a reason when the run's outcome is known.
        stop_on_collision: treat the first collision as deciding the run.
    """

    def __init__(self, robots: tuple[str, ...], cell_m: float) -> None:
        super().__init__(robots, cell_m)
        self.start_ms: dict[str, int] = {}
        self.stuck: set[str] = set()
        self.first_collision_ms: int | None = None
        self.on_decided: Callable[[str], None] | None = None
        self.stop_on_collision = False
        self._decided = False

    def on_message(self, topic: str, msg: Any) -> None:
        """Account for one message, then check whether the run is decided."""
        super().on_message(topic, msg)
        if isinstance(msg, RobotStatus) and msg.robot in self.records:
            if msg.mode == "planning":
                self.start_ms.setdefault(msg.robot, msg.time_ms)
            elif msg.mode == "stuck":
                self.stuck.add(msg.robot)
        elif isinstance(msg, Collision) and self.first_collision_ms is None:
            self.first_collision_ms = msg.time_ms
        self._check_decided()

    def _check_decided(self) -> None:
        if self._decided or self.on_decided is None:
            return
        reason = None
        if self.collisions and self.stop_on_collision:
            c = self.collisions[0]
            reason = f"collision {c.robot_a}-{c.robot_b} at t={c.time_ms} ms"
        elif all(r.arrived or name in self.stuck for name, r in self.records.items()):
            reason = "every robot arrived" if not self.stuck else (
                "every robot arrived or is stuck (" + ", ".join(sorted(self.stuck)) + ")")
        if reason is not None:
            self._decided = True
            self.on_decided(reason)


def timed_report_for(scenario: Any) -> TimedReport | None:
    """Report factory for `live.report`: a `TimedReport` for a fleet with a map server."""
    for cfg in scenario.nodes:
        if hasattr(cfg.params, "robots") and hasattr(cfg.params, "map"):
            report = TimedReport(tuple(cfg.params.robots), load_map(cfg.params.map).resolution)
            hook = _HOOK.get()
            if hook is not None:
                hook(report)
            return report
    return None


@final
@dataclass(slots=True)
class LiveRunResult:
    """What one live run did.

    Times are fleet ms since the launcher's epoch; `durations_ms` are per robot
    from its own start to its arrival, the quantity the checker predicts.
    """

    seed: int
    time_scale: float
    reason: str
    wall_s: float
    failed_nodes: tuple[str, ...]
    collisions: list[tuple[str, str, int]] = field(default_factory=list)
    arrived: dict[str, bool] = field(default_factory=dict)
    start_ms: dict[str, int | None] = field(default_factory=dict)
    arrival_ms: dict[str, int | None] = field(default_factory=dict)
    stuck: tuple[str, ...] = ()
    interrupted: bool = False
    exit_codes: dict[str, int | None] = field(default_factory=dict)
    #: a node died of a signal the launcher did not send (`EndReason.NODE_KILLED`): the run
    #: says nothing about the fleet, another program or the OOM killer ended it
    killed_from_outside: bool = False
    terminated: bool = False  # a SIGTERM, not a Ctrl-C, interrupted it (exit 143, not 130)

    @property
    def all_arrived(self) -> bool:
        """Every robot reported arrival."""
        return bool(self.arrived) and all(self.arrived.values())

    @property
    def passed(self) -> bool:
        """Every robot arrived, no collision, no node failed."""
        return self.all_arrived and not self.collisions and not self.failed_nodes

    @property
    def verdict(self) -> str:
        """One word or phrase: passed, collision, not arrived, node failure."""
        if self.failed_nodes:
            return "node failure: " + ", ".join(self.failed_nodes)
        if self.collisions:
            a, b, t = self.collisions[0]
            return f"collision {a}-{b} at {t / 1000:.2f} s"
        if not self.all_arrived:
            missing = [r for r, ok in self.arrived.items() if not ok]
            return "not arrived: " + ", ".join(missing)
        return "passed"

    @property
    def durations_ms(self) -> dict[str, int | None]:
        """Per robot: arrival minus its own start (None if either is unknown)."""
        out: dict[str, int | None] = {}
        for name, arrival in self.arrival_ms.items():
            start = self.start_ms.get(name)
            out[name] = None if arrival is None or start is None else arrival - start
        return out

    @property
    def start_spread_ms(self) -> int | None:
        """Latest minus earliest robot start: how far the live starts are from simultaneous."""
        starts = [s for s in self.start_ms.values() if s is not None]
        return max(starts) - min(starts) if starts else None

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready record."""
        data = dataclasses.asdict(self)
        data.update(passed=self.passed, verdict=self.verdict, durations_ms=self.durations_ms)
        return data


def private_copy(scenario: Scenario, directory: str | Path,
                 params: Sequence[str] = ()) -> Scenario:
    """The scenario loaded from a copy in `directory`, its file parameters made absolute
    (and the parameter overrides `params` written into it, `runtime.scenario.overrides`).

    Node processes are started with the scenario's path on their command line,
    and test suites find (and kill) a fleet's processes by that path; a copy
    keeps the experiment's fleets apart from anyone else's run of the same file,
    and freezes the file for the whole experiment.
    """
    source = scenario.path
    if source is None:
        raise ValueError(f"scenario {scenario.name!r} has no file to copy (built in Python)")
    doc = yaml.safe_load(Path(source).read_text())
    if params:  # validated as every command validates them, then written in
        scenario = load_with_params(source, params)
        doc.update(overrides_doc(Path(source), params))
    doc = with_absolute_files(doc, scenario)
    out = Path(directory) / Path(source).name
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(f"# Copy of {scenario.path} for live runs (file parameters made absolute).\n"
                   + yaml.safe_dump(doc, sort_keys=False))
    return load_scenario(out)


def with_timed_report(scenario: Scenario) -> Scenario:
    """The same scenario with `live.report` set to `TimedReport` (the nodes are unaffected:
    node processes read the file, and the report lives in the launcher)."""
    return dataclasses.replace(scenario,
                               live=dataclasses.replace(scenario.live, report=REPORT_FACTORY))


async def live_run(scenario: Scenario, *, time_scale: float, seed: int, timeout_s: float,
                   out: TextIO, stop_on_collision: bool = True,
                   handle_signals: bool = True) -> LiveRunResult:
    """Run the fleet once; stop it as soon as its outcome is decided.

    Args:
        scenario: a loaded scenario whose map server has a `robots` list.
        time_scale: fleet ms per wall ms.
        seed: fleet seed.
        timeout_s: wall seconds before the run is ended regardless.
        out: where the nodes' output lines go.
        stop_on_collision: end the run at the first collision (its outcome is then known).
        handle_signals: let SIGINT/SIGTERM end the run (the caller sees `interrupted`).
    """
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    decided = asyncio.Event()
    why: list[str] = []
    reports: list[TimedReport] = []

    def hook(report: TimedReport) -> None:
        report.stop_on_collision = stop_on_collision
        def on_decided(reason: str) -> None:
            why.append(reason)
            decided.set()
        report.on_decided = on_decided
        reports.append(report)

    token = _HOOK.set(hook)
    started = time.monotonic()
    try:
        options = LaunchOptions(time_scale=time_scale, timeout_s=timeout_s, seed=seed,
                                listen=endpoint, handle_signals=handle_signals)
        fleet = asyncio.create_task(run_fleet(with_timed_report(scenario), options, out=out))
        stopper = asyncio.create_task(_stop_when_decided(decided, fleet, endpoint,
                                                         scenario.fleet, why))
        try:
            result = await fleet
        finally:
            stopper.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await stopper
    finally:
        _HOOK.reset(token)
    report = reports[0] if reports else result.report
    record = LiveRunResult(seed=seed, time_scale=time_scale, reason=result.reason,
                       wall_s=time.monotonic() - started, failed_nodes=tuple(result.failed),
                       interrupted=result.interrupted, exit_codes=dict(result.exit_codes),
                       killed_from_outside=result.end is EndReason.NODE_KILLED,
                       terminated=result.end is EndReason.TERMINATED)
    if isinstance(report, TimedReport):
        record.collisions = [(c.robot_a, c.robot_b, c.time_ms) for c in report.collisions]
        record.arrived = {n: r.arrived for n, r in report.records.items()}
        # FleetReport's arrival counts from the robot's own start; keep fleet time here.
        record.arrival_ms = {n: None if r.arrival_ms is None or r.start_ms is None
                             else r.arrival_ms + r.start_ms for n, r in report.records.items()}
        record.start_ms = {n: report.start_ms.get(n) for n in report.records}
        record.stuck = tuple(sorted(report.stuck))
    return record


async def _stop_when_decided(decided: asyncio.Event, fleet: asyncio.Task[Any], endpoint: str,
                             fleet_name: str, why: list[str]) -> None:
    """Once decided, give the fleet a moment to end by itself, then ask it to stop."""
    await decided.wait()
    await asyncio.wait([fleet], timeout=0.3)
    if fleet.done():
        return
    auth = registry_auth(endpoint)  # the launcher registered its fleet: its key and login
    transport = ZenohTransport(zenoh_config(connect=[endpoint],
                                            settings=login_settings(auth, write=True)),
                               key=auth.key)
    await transport.open()
    try:
        payload = encode(String(f"outcome decided: {why[0]}"), sender="experiment")
        for _ in range(20):  # repeat until the launcher has heard it
            transport.put(topic_key(fleet_name, SHUTDOWN_TOPIC), payload, QOS_DEFAULT)
            await asyncio.wait([fleet], timeout=0.5)
            if fleet.done():
                return
    finally:
        await transport.close()
