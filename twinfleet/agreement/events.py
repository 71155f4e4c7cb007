"""Live event logs (format ``twinfleet-events/2``) and how their events correspond to
the checker's.

`twinfleet launch SCENARIO --record-events FILE` makes every node process log
each event it dispatches (the runtime's event log); the launcher merges the
per-node logs into FILE: a ``fleet`` header line, one ``header`` line per
node, then one line per event in dispatch-time order::

    {"node": "r1", "i": 7, "t": 897, "kind": "delivery", "handler": "on_scan",
     "sender": "map_server", "topic": "/r1/scan", "seq": 3, "stamp": 893, "due": null,
     "args": "1fbe1fd230dddbf1", "summary": "Scan(robot='r1', ...)",
     "choices": [], "options": [], "digest": "98e2f8602e3277dcf81e4b54"}

``t`` is the fleet ms at dispatch, ``stamp`` the sender's fleet ms at send,
``due`` the due time of a timer, ``args`` the `runtime.host.replay_gate.payload_digest` of
the handler's arguments, ``digest`` the `runtime.host.replay_gate.state_digest` of the
node's state after the handler; ``error`` is present when the handler raised.

``kind`` is an `EventKind` value, the same vocabulary as the checker's events:
``start`` (`@on_start`), ``delivery``, ``request``, ``reply``, ``timeout`` (a
call got no answer in time: its reply handler gets a `CallError`), ``timer``
(`ctx.after`), ``periodic`` (`@every`), ``liveliness`` (a node appearing or
disappearing) and ``crash`` (the node's process died and was respawned: the
checker's crash fault, followed by the new process's ``start`` events). A live event and a checker event correspond when node,
handler, kind, sender and argument digest agree (`Signatures`, `live_signature`).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, final

from twinfleet.checker.choices import PrefixChooser
from twinfleet.checker.world import Event
from twinfleet.runtime.contract.context import Context
from twinfleet.runtime.contract.dispatch import run_handler
from twinfleet.runtime.contract.kinds import EventKind
from twinfleet.runtime.core.eventlog import EVENTS_FORMAT, payload_digest, with_restarts
from twinfleet.runtime.scenario.spec import Scenario

if TYPE_CHECKING:
    from twinfleet.checker.system import System

#: The event-log format this reader understands (the runtime's event log writes it).

Signature = tuple[str, str, EventKind, str, str]  # node, handler, kind, sender, args digest


class EventLogError(ValueError):
    """An event log is unreadable or not in the supported format."""


@final
@dataclass(frozen=True, slots=True)
class LiveEvent:
    """One dispatched event of a live run (one line of an event log)."""

    node: str
    index: int  # position in the node's own log, from 0
    t: int  # fleet ms when it was dispatched
    kind: EventKind
    handler: str
    sender: str
    args: str  # payload digest of the handler's arguments
    digest: str  # state digest of the node after the handler
    choices: tuple[int, ...] = ()
    options: tuple[int, ...] = ()
    topic: str = ""
    seq: int = 0
    stamp: int | None = None
    due: int | None = None
    summary: str = ""
    error: str | None = None
    line: int = 0  # line in the file, from 1

    @classmethod
    def from_record(cls, rec: dict[str, Any], line: int = 0) -> LiveEvent:
        """Build from one parsed JSON line."""
        return cls(node=rec["node"], index=int(rec["i"]), t=int(rec["t"]),
                   kind=EventKind(rec["kind"]),
                   handler=rec["handler"], sender=rec.get("sender", ""), args=rec["args"],
                   digest=rec["digest"], choices=tuple(rec.get("choices", ())),
                   options=tuple(rec.get("options", ())), topic=rec.get("topic", ""),
                   seq=rec.get("seq", 0), stamp=rec.get("stamp"), due=rec.get("due"),
                   summary=rec.get("summary", ""), error=rec.get("error"), line=line)

    def label(self) -> str:
        """``r1.update_moving_status(True) (timer)``, arguments cut at 40 characters."""
        source = "" if self.sender in ("", self.node) else f" from {self.sender}"
        args = self.summary if len(self.summary) <= 40 else self.summary[:37] + "..."
        return f"{self.node}.{self.handler}({args}) ({self.kind}{source})"

    def where(self) -> str:
        """Where it is in the log: node event number, live time and file line."""
        return f"{self.node} event #{self.index}, live t={self.t} ms, line {self.line}"


@final
@dataclass
class EventLogFile:
    """A merged event log: its headers and every event in dispatch-time order."""

    path: str
    header: dict[str, Any]
    node_headers: dict[str, dict[str, Any]]
    events: list[LiveEvent] = field(default_factory=list)

    def by_node(self) -> dict[str, list[LiveEvent]]:
        """Each node's events in its own order."""
        out: dict[str, list[LiveEvent]] = {}
        for ev in self.events:
            out.setdefault(ev.node, []).append(ev)
        for events in out.values():
            events.sort(key=lambda e: e.index)
        return out


def load_events(path: str | Path) -> EventLogFile:
    """Read a merged event log, or the ``PATH.parts`` directory a killed launcher left."""
    p = Path(path)
    parts = Path(f"{path}.parts")
    if not p.exists() and parts.is_dir():
        return _load_parts(path, parts)
    try:
        lines = p.read_text().splitlines()
    except OSError as exc:
        raise EventLogError(f"{path}: cannot read event log: {exc}") from None
    log = EventLogFile(str(path), {}, {})
    for n, line in enumerate(lines, start=1):
        rec = _parse(path, n, line, last=n == len(lines))
        if rec is not None:
            _add(log, rec, n)
    if not log.header and not log.node_headers:
        raise EventLogError(f"{path}: not a {EVENTS_FORMAT} event log (no header line)")
    return log


def _load_parts(path: str | Path, parts: Path) -> EventLogFile:
    log = EventLogFile(str(path), {"kind": "fleet", "format": EVENTS_FORMAT}, {})
    for part in sorted(parts.glob("*.jsonl")):
        lines = part.read_text().splitlines()
        records = [rec for n, line in enumerate(lines, start=1)
                   if (rec := _parse(part, n, line, last=n == len(lines))) is not None]
        heads = [r for r in records if r.get("kind") == "header"]
        for rec in heads[:1]:
            _add(log, rec, 0)
        events, restarted = with_restarts(records)
        if restarted and heads:
            log.header.setdefault("restarts", {})[heads[0]["node"]] = restarted
        for n, rec in enumerate(events, start=1):
            _add(log, rec, n)
    log.events.sort(key=lambda e: e.t)
    return log


def _parse(path: str | Path, n: int, line: str, *, last: bool) -> dict[str, Any] | None:
    if not line.strip():
        return None
    try:
        rec = json.loads(line)
    except json.JSONDecodeError as exc:
        if last:
            return None  # a torn last line of a killed process
        raise EventLogError(f"{path}:{n}: not JSON: {exc}") from None
    if rec.get("kind") in ("fleet", "header") and rec.get("format") != EVENTS_FORMAT:
        raise EventLogError(f"{path}:{n}: format {rec.get('format')!r}, expected {EVENTS_FORMAT}")
    return rec


def _add(log: EventLogFile, rec: dict[str, Any], n: int) -> None:
    kind = rec.get("kind")
    if kind == "fleet":
        log.header = rec
    elif kind == "header":
        if rec["node"] in log.node_headers:
            log.header.setdefault("restarts", {}).setdefault(rec["node"], 0)
            log.header["restarts"][rec["node"]] += 1
        else:
            log.node_headers[rec["node"]] = rec
    else:
        try:
            log.events.append(LiveEvent.from_record(rec, n))
        except (KeyError, TypeError, ValueError) as exc:
            raise EventLogError(f"{log.path}:{n}: bad event record ({exc!r})") from None


# ------------------------------------------------------------ checker side


@final
class Signatures:
    """The identity (node, handler, kind, sender, args digest) of checker events, cached."""

    def __init__(self, system: System) -> None:
        self.system = system
        self._cache: dict[bytes, Signature] = {}

    def of(self, ev: Event) -> Signature:
        """(node, handler, kind, sender, args digest) of `ev`."""
        sig = self._cache.get(ev.key)
        if sig is None:
            names = self.system.names
            sender = names[ev.sender] if 0 <= ev.sender < len(names) else ""
            sig = (names[ev.target], ev.method, ev.kind, sender, payload_digest(ev.args))
            self._cache[ev.key] = sig
        return sig


def live_signature(ev: LiveEvent) -> Signature:
    """(node, handler, kind, sender, args digest) of a live event."""
    return (ev.node, ev.handler, ev.kind, ev.sender, ev.args)


def split_start_choices(scenario: Scenario,
                        choices: Sequence[int]) -> dict[tuple[str, str], tuple[int, ...]]:
    """Which of the initial world's `ctx.choose` answers each start handler made.

    The checker runs every `@on_start` at t=0 in scenario order with one chooser
    (`System.initial_world`); live, each node makes only its own. Keys are
    (node, handler method).
    """
    rest = list(choices)
    out: dict[tuple[str, str], tuple[int, ...]] = {}
    for cfg in scenario.nodes:
        node = cfg.instantiate()
        node.state = node.initial_state()
        for spec in node.spec().of_kind("start"):
            chooser = PrefixChooser(rest)
            run_handler(node, spec.method, Context(node, 0, chooser))
            used = len(chooser.indices)
            out[(cfg.name, spec.method)] = tuple(rest[:used])
            rest = rest[used:]
    return out


def refuse_unreplayable(system: System, *, gated: bool) -> None:
    """Raise ValueError when the scenario adds checker branches a live run cannot take.

    No live node records the checker's latency and fault branches. `validate`
    (``gated=False``) searches them: any delay, drop or duplicate the checker
    allows may explain what the live run did, and a live restart is a crash fault.
    A gated replay (``gated=True``) takes latency and drop branches itself — it
    grants a delivery at its delayed time, or never — but cannot make Zenoh
    deliver a message twice nor a node late for its timers (its crash steps are
    refused one by one).
    """
    s = system.settings
    if gated and s.duplicate:
        raise ValueError(f"{system.scenario.path}: check.faults.duplicate cannot be replayed "
                         "live (a live message arrives once)")
    if gated and s.timer_lateness is not None:
        raise ValueError(f"{system.scenario.path}: check.timer_lateness cannot be replayed "
                         "live (the gate grants a tick when it is due)")

