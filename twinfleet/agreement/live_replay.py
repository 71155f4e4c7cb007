"""`twinfleet replay TRACE --live`: a checker trace re-enacted by the real fleet over Zenoh.

The launcher starts every node process of the trace's scenario in *gated*
mode (``node_main --gate``): the node keeps a logical clock and holds every
ready event — deliveries, requests, replies, timers, its `@on_start` — in a
`runtime.host.replay_gate.ReplayGate` until it is granted. The coordinator here runs in
the launcher process, on its router session, as the fleet's driver
(`runtime.fleet.launcher.run_fleet(driver=...)`):

1. It re-executes the trace in-process with the checker (`System.step` on
   each recorded step, digests checked against the file), which gives, for every step, the exact
   event (node, handler, kind, sender, argument digest), its logical time,
   the `ctx.choose` answers and the node's state digest after it.
2. Once every node's liveliness token is up, it grants each node's start
   handlers at t=0, then the trace's steps one at a time, with a Zenoh query
   to the node's gate; the node runs the event when it has it (a message may
   still be in flight), with ``ctx.now()`` the step's logical time and the
   recorded choices, performs its effects on Zenoh and answers with its state
   digest, the choices it made and what it published. Any difference stops
   the replay with the step, what was expected and what the node did.
   Each granted handler must also log (``ctx.log``) what the checker's run of
   its step logged: the answer's `logs_digest` equals the one computed here.
3. At the end it checks that the live fleet shows the trace's violation: each
   node's state digest equals the checker's final world (so the violated
   invariant holds of the real processes' states), and the nodes' own event
   logs (``--record-events``) list the same events in the same order per node.

Timers fire when granted, not by wall clock, so the replay runs as fast as
the processes go, whatever the trace's logical duration. A lasso trace (a
liveness violation) is followed by `cycles` more rounds of its cycle; each
round must bring every live node back to the state digests it had where the
cycle starts.

Latency and drop branches of `check.latency` / `check.faults` are the
coordinator's to take, not the nodes': a delayed delivery is granted at its
delayed logical time, a dropped one never (the node keeps holding it), and a
node is asked only for its own `ctx.choose` answers (`Transition.branches` says
which of a step's choices are the checker's). A duplicated message or a crash
is refused.
"""

from __future__ import annotations

import asyncio
import builtins
import io
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO, final

from twinfleet.agreement.events import (
    live_signature,
    load_events,
    refuse_unreplayable,
    split_start_choices,
)
from twinfleet.checker.driver import load, system_for_trace
from twinfleet.checker.system import System
from twinfleet.checker.trace import NondeterminismError, recorded_step, replay_step
from twinfleet.checker.world import World
from twinfleet.runtime.contract.kinds import EventKind
from twinfleet.runtime.contract.messages import CallFailure
from twinfleet.runtime.contract.tracefile import TraceError, code_changes, load_trace
from twinfleet.runtime.core.eventlog import payload_digest, state_digest, summarise
from twinfleet.runtime.fleet.fleet_result import EndReason, signal_exit_code
from twinfleet.runtime.fleet.launcher import Fleet, LaunchOptions, format_result, run_fleet
from twinfleet.runtime.host.keys import KeyKind, kind_expr, node_key, parse_node_key
from twinfleet.runtime.host.replay_wire import (
    STATUS,
    GateStatus,
    Grant,
    GrantAnswer,
    WireError,
    logs_digest,
)
from twinfleet.runtime.host.transport import Transport
from twinfleet.runtime.scenario.spec import Scenario


class ReplayDivergence(RuntimeError):
    """The live fleet did not do what the trace says at some step."""


@final
@dataclass(frozen=True, slots=True)
class Planned:
    """One grant of the plan (`grant.step` 0: a start handler), and what the node must
    report after it."""

    node: str
    grant: Grant
    summary: str  # the event's arguments, shortened for messages
    options: tuple[int, ...] | None  # None: not checked (a node's earlier start handlers)
    digest: str | None
    logs: str | None = None  # `logs_digest` of the step's ctx.log records; None: not checked


@final
@dataclass
class Plan:
    """A trace compiled into grants, with what the live fleet must show at the end."""

    trace_path: str
    trace: Mapping[str, Any]
    scenario: Scenario
    starts: list[Planned]
    steps: list[Planned]
    final_digests: dict[str, str]
    cycles: int = 0  # extra rounds of a lasso's cycle appended to the trace's steps
    #: each node's state digest before any grant: a node the trace never runs keeps it
    initial_digests: dict[str, str] = field(default_factory=dict)


@final
@dataclass
class LiveReplayResult:
    """What the live replay did and found."""

    trace: str
    property: str
    message: str
    steps: int
    granted: int = 0
    divergence: str | None = None
    final_states_match: bool = False
    node_logs: str = ""
    node_logs_match: bool | None = None
    events_path: str = ""
    cycles: int = 0
    cycle_start: int | None = None
    startup_s: float = 0.0
    replay_s: float = 0.0
    wall_s: float = 0.0
    fleet_reason: str = ""
    fleet_end: EndReason | None = None  # what ended the replay's fleet

    @builtins.property  # the class has a field named `property`
    def confirmed(self) -> bool:
        """Every step ran (and logged) as recorded, and the final states agree."""
        return (self.divergence is None and self.granted > 0 and self.final_states_match
                and self.node_logs_match is not False)

    def summary(self) -> str:
        """A human-readable report."""
        lines = [f"live replay of {self.trace}: {self.granted} grants "
                 f"({self.steps} trace steps) in {self.replay_s:.2f} s "
                 f"(fleet start {self.startup_s:.2f} s, total {self.wall_s:.2f} s)"]
        if self.divergence:
            lines.append(f"DIVERGED: {self.divergence}")
        lines.append("final node states: " + ("equal to the checker's final world"
                                              if self.final_states_match else "NOT reached"))
        if self.divergence is None and self.granted:
            lines.append("handler logs: every granted handler logged what its trace step logged")
        if self.node_logs:
            lines.append(f"node event logs: {self.node_logs} ({self.events_path})")
        if self.cycles:
            lines.append(f"lasso: went round the cycle from world {self.cycle_start} "
                         f"{self.cycles} more time(s)"
                         + ("; every round came back to the same node states"
                            if self.divergence is None and self.final_states_match else ""))
        verdict = "CONFIRMED" if self.confirmed else "NOT confirmed"
        lines.append(f"live replay {verdict}: {self.property} ({self.message})")
        return "\n".join(lines)


def plan(trace_path: str | Path, *, cycles: int = 0) -> Plan:
    """Compile a trace: re-execute it with the checker and list the grants.

    Args:
        trace_path: a trace written by `twinfleet check`.
        cycles: for a lasso trace (a liveness violation), go round its cycle this
            many more times after the recorded steps. The world at the end of each
            round equals (up to a shift of time) the one where the cycle starts, so
            the live nodes must come back to the same state digests every round.

    Raises:
        TraceError: unreadable trace, or the code no longer produces it.
        ValueError: the trace needs branches a live fleet cannot take (a duplicated message,
            a crash).
    """
    if cycles < 0:
        raise ValueError(f"cycles must be >= 0, got {cycles}")
    trace = load_trace(trace_path)
    system, _ = system_for_trace(trace)
    scenario = system.scenario
    refuse_unreplayable(system, gated=True)
    choices = tuple(trace["initial"]["choices"])
    init = system.initial_world(choices)
    if init.world.digest.hex() != trace["initial"]["digest"]:
        raise TraceError(f"{trace_path}: the initial world differs from the trace's (the code "
                         "or the scenario changed; `twinfleet replay` says more)")
    # the start handlers' own answers; the checker's branches on their messages are the
    # grants' to take, like every later step's
    start_choices = split_start_choices(scenario, _handler_part(choices, init.branches))
    starts = _start_grants(system, init.world.states, start_choices)
    records = list(trace["steps"])
    if cycles and trace.get("cycle_start") is not None:
        records += records[trace["cycle_start"]:] * cycles
    else:
        cycles = 0
    steps, world = _step_grants(system, init.world, records, str(trace_path))
    final = {name: state_digest(world.states[i]) for i, name in enumerate(system.names)}
    initial = {name: state_digest(init.world.states[i]) for i, name in enumerate(system.names)}
    return Plan(str(trace_path), trace, scenario, starts, steps, final, cycles, initial)


def _step_grants(system: System, world: World, records: Sequence[Mapping[str, Any]],
                 where: str) -> tuple[list[Planned], World]:
    """The grants of a trace's step records, taken from `world`, and the world at the end."""
    steps = []
    for n, rec in enumerate(records, start=1):
        if rec.get("kind") == EventKind.DROP:
            raise ValueError(f"{where}: step {rec['index']} is a KEEP_LAST drop; a live "
                             "replay holds every message and cannot drop one on cue")
        if rec.get("kind") == EventKind.CRASH:
            raise ValueError(f"{where}: step {rec['index']} is a crash fault; a live "
                             "replay cannot crash a node on cue")
        try:
            t = replay_step(system, world, recorded_step(system, world, rec))
        except NondeterminismError as exc:
            raise TraceError(f"{where}: {exc}") from None
        if t.world.digest.hex() != rec["digest"]:
            raise TraceError(f"{where}: step {rec['index']} no longer gives the recorded "
                             "world (run `twinfleet replay` for details)"
                             + (f" (round of the cycle, step {n})" if n > rec["index"] else ""))
        ev = t.event
        sender = system.names[ev.sender] if ev.sender >= 0 else ""
        # the node answers its own ctx.choose; latency and drop branches are the grants' timing
        grant = Grant(ev.kind, ev.method, sender, payload_digest(ev.args), ev.due,
                      _handler_part(t.step.choices, t.branches), n)
        steps.append(Planned(system.names[ev.target], grant, summarise(ev.args),
                             _handler_part(t.step.options, t.branches),
                             state_digest(t.world.states[ev.target]), logs_digest(t.logs)))
        world = t.world
    return steps, world


def _handler_part(values: Sequence[int], branches: Sequence[int]) -> tuple[int, ...]:
    """The handlers' own answers among a step's choices (or options): all but the branches."""
    skip = set(branches)
    return tuple(v for p, v in enumerate(values) if p not in skip)


def _start_grants(system: System, states: Sequence[bytes],
                  choices: Mapping[tuple[str, str], tuple[int, ...]]) -> list[Planned]:
    grants = []
    for i, node in enumerate(system.nodes):
        specs = node.spec().of_kind("start")
        for n, spec in enumerate(specs):
            last = n == len(specs) - 1
            grant = Grant(EventKind.START, spec.method, node.name, payload_digest(()), 0,
                          choices.get((node.name, spec.method), ()))
            grants.append(Planned(node.name, grant, "", None,
                                  state_digest(states[i]) if last else None))
    return grants


@final
class Coordinator:
    """Grants a plan's events to a gated fleet, one at a time (module docstring)."""

    def __init__(self, plan: Plan, result: LiveReplayResult, *, step_timeout_s: float = 10.0,
                 ready_timeout_s: float = 30.0) -> None:
        self.plan, self.result = plan, result
        self.step_timeout_s, self.ready_timeout_s = step_timeout_s, ready_timeout_s
        self.alive: set[str] = set()
        self.transport: Transport | None = None
        self.digests: dict[str, str] = dict(plan.initial_digests)
        self._changed = asyncio.Event()

    async def __call__(self, fleet: Fleet) -> str:
        """The fleet's driver (`run_fleet(driver=...)`): `run` on the launcher's session."""
        assert fleet.transport is not None
        return await self.run(fleet.transport)

    async def run(self, transport: Transport) -> str:
        """Wait for the nodes, grant every event, check the end; return the end reason."""
        self.transport = transport
        name = self.plan.scenario.fleet
        transport.watch(kind_expr(name, KeyKind.NODE), self._on_alive)
        started = begin = time.monotonic()
        try:
            await self._wait_alive()
            begin = time.monotonic()
            self.result.startup_s = begin - started
            for planned in [*self.plan.starts, *self.plan.steps]:
                await self._grant(planned)
                self.result.granted += 1
        except ReplayDivergence as exc:
            self.result.divergence = str(exc)
            return f"live replay diverged: {exc}"
        finally:
            self.result.replay_s = time.monotonic() - begin
        self.result.final_states_match = all(self.digests.get(n) == d
                                             for n, d in self.plan.final_digests.items())
        return f"live replay done: {self.result.granted} events granted"

    def _on_alive(self, key: str, alive: bool) -> None:
        node = parse_node_key(key, KeyKind.NODE).node
        (self.alive.add if alive else self.alive.discard)(node)
        self._changed.set()

    async def _wait_alive(self) -> None:
        wanted = {cfg.name for cfg in self.plan.scenario.nodes}
        deadline = time.monotonic() + self.ready_timeout_s
        while not wanted <= self.alive:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise ReplayDivergence("nodes not alive after "
                                       f"{self.ready_timeout_s:g} s: "
                                       + ", ".join(sorted(wanted - self.alive)))
            self._changed.clear()
            try:
                await asyncio.wait_for(self._changed.wait(), remaining)
            except TimeoutError:
                continue

    async def _grant(self, planned: Planned) -> None:
        answer, grant = await self._ask(planned), planned.grant
        where = f"step {grant.step}: {planned.node}.{grant.handler} ({grant.kind}) at t={grant.t}"
        if answer.error:
            raise ReplayDivergence(f"{where}: the live handler failed: {answer.error}")
        if answer.choices != grant.choices or (planned.options is not None
                                               and answer.options != planned.options):
            raise ReplayDivergence(f"{where}: ctx.choose answered {list(answer.choices)} of "
                                   f"options {list(answer.options)}, the trace has "
                                   f"{list(grant.choices)} of {list(planned.options or ())}")
        if planned.logs is not None and answer.logs != planned.logs:
            raise ReplayDivergence(f"{where}: the live handler's ctx.log records differ from "
                                   "the checker's run of the step (see the node's output)")
        if planned.digest is not None and answer.digest != planned.digest:
            raise ReplayDivergence(f"{where}: live state digest {answer.digest}, the checker's "
                                   f"is {planned.digest} (the node's state differs)")
        self.digests[planned.node] = answer.digest

    async def _ask(self, planned: Planned) -> GrantAnswer:
        transport, grant = self.transport, planned.grant
        key = node_key(self.plan.scenario.fleet, KeyKind.REPLAY, planned.node)
        reason = ""
        for _ in range(100):  # the queryable may not be routed yet just after the token
            reply, failure, reason = await _query(transport, key, grant.encode(),
                                                  self.step_timeout_s)
            if reply is not None:
                try:
                    return GrantAnswer.decode(reply)
                except WireError as exc:
                    raise ReplayDivergence(f"step {grant.step}: {planned.node}: {exc}") from None
            if failure is not CallFailure.NO_SERVER:
                break
            await asyncio.sleep(0.05)
        raise ReplayDivergence(f"step {grant.step}: {planned.node} did not run "
                               f"{grant.handler}({planned.summary[:60]}) ({grant.kind} from "
                               f"{grant.sender}) within {self.step_timeout_s:g} s "
                               f"({reason}){await self._holds(key)}")

    async def _holds(self, key: str) -> str:
        """What a node that did not run its grant holds, for the message."""
        reply, _, _ = await _query(self.transport, key, STATUS, 2.0)
        try:
            status = GateStatus.decode(reply) if reply is not None else None
        except WireError:
            status = None
        if status is None:
            return ""
        return "; node holds: " + (", ".join(
            f"{h.handler}({h.summary[:40]}) ({h.kind} from {h.sender})"
            for h in status.ready[:8]) or "nothing")


async def _query(transport: Transport | None, key: str, payload: bytes,
                 timeout_s: float) -> tuple[bytes | None, CallFailure | None, str]:
    assert transport is not None
    done: asyncio.Future[tuple[bytes | None, CallFailure | None, str]] = \
        asyncio.get_running_loop().create_future()

    def on_done(reply: bytes | None, failure: CallFailure | None, reason: str) -> None:
        if not done.done():
            done.set_result((reply, failure, reason))

    transport.query(key, payload, timeout_s * 1000.0, on_done)
    return await done


async def replay_live(trace_path: str | Path, *, out: TextIO = sys.stdout,
                      step_timeout_s: float = 10.0, timeout_s: float = 300.0,
                      events_out: str | None = None, handle_signals: bool = False,
                      cycles: int = 0) -> LiveReplayResult:
    """Replay a checker trace on the real multi-process fleet (module docstring).

    Args:
        trace_path: a trace written by `twinfleet check`.
        out: where the fleet's prefixed output lines go.
        step_timeout_s: wall seconds a node may take to run one granted event.
        timeout_s: wall seconds for the whole run.
        events_out: where the nodes' merged event log goes (default: beside the trace,
            ``<trace stem>.live-events.jsonl``).
        handle_signals: end the run on SIGINT/SIGTERM (main thread only).
        cycles: for a lasso trace, extra rounds of its cycle (see `plan`).
    """
    started = time.monotonic()
    p = plan(trace_path, cycles=cycles)
    prop = p.trace["property"]["name"]
    result = LiveReplayResult(str(trace_path), prop, p.trace.get("message", ""), len(p.steps),
                              cycles=p.cycles,
                              cycle_start=p.trace.get("cycle_start"))
    coordinator = Coordinator(p, result, step_timeout_s=step_timeout_s)
    events = events_out or str(Path(trace_path).with_suffix(".live-events.jsonl"))
    options = LaunchOptions(timeout_s=timeout_s, handle_signals=handle_signals,
                            record_events=events, node_args=("--gate",),
                            params=tuple(p.trace.get("params") or ()))  # the overrides checked
    fleet = await run_fleet(p.scenario, options, out=out, driver=coordinator)
    result.fleet_reason, result.fleet_end = fleet.reason, fleet.end
    for line in format_result(fleet):
        print(f"[launcher] {line}", file=out, flush=True)
    result.node_logs_match, result.node_logs = compare_node_logs(p, events)
    result.events_path = events
    result.wall_s = time.monotonic() - started
    return result


def compare_node_logs(p: Plan, events_path: str) -> tuple[bool | None, str]:
    """Do the nodes' own event logs list the granted events, in order, per node?"""
    try:
        log = load_events(events_path)
    except (OSError, ValueError) as exc:
        return None, f"unreadable ({exc})"
    by_node = log.by_node()
    expected: dict[str, list[tuple[str, str, str, str]]] = {}
    for planned in [*p.starts, *p.steps]:
        g = planned.grant
        expected.setdefault(planned.node, []).append((g.handler, g.kind, g.sender, g.args))
    for node, want in expected.items():
        got = [live_signature(e)[1:] for e in by_node.get(node, [])]
        if got != want:
            n = next((i for i, (a, b) in enumerate(zip(got, want, strict=False)) if a != b),
                     min(len(got), len(want)))
            return False, (f"{node}'s log differs at its event #{n}: "
                           f"{got[n] if n < len(got) else 'nothing'} instead of {want[n]}")
    total = sum(len(v) for v in expected.values())
    return True, f"the same {total} events in the same order per node as the trace"


def live_replay_command(args: Any) -> int:
    """`twinfleet replay TRACE --live`: exit 1 when the violation is confirmed live, 2 when
    not (or on bad input), like `replay`. A node whose code changed since the trace is
    said first, as `replay` says it."""
    try:
        trace = load_trace(args.trace)
        if trace.get("scenario") is not None:  # else `plan` says it has no scenario file
            scenario = load(trace["scenario"], params=trace.get("params") or ())
            for line in code_changes(trace, {cfg.name: cfg.cls for cfg in scenario.nodes}):
                print(f"twinfleet replay --live: warning: {line}", file=sys.stderr)
        result = asyncio.run(replay_live(args.trace, out=io.StringIO() if args.quiet
                                         else sys.stdout, handle_signals=True,
                                         cycles=getattr(args, "cycles", 0)))
    except (TraceError, ValueError, OSError) as exc:
        print(f"twinfleet replay --live: {exc}", file=sys.stderr)
        return 2
    print(result.summary() if not args.quiet else result.summary().splitlines()[-1])
    return signal_exit_code(result.fleet_end) or (1 if result.confirmed else 2)
