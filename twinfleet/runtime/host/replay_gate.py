"""The replay gate of a live node: only the events a replay coordinator grants run.

A gated node (``node_main --gate``) runs on a `LogicalClock` over a
`runtime.core.node_core.NodeCore` that holds every message it receives (no KEEP_LAST)
and every timer it arms; nothing runs by itself. The coordinator
(`twinfleet.agreement.live_replay`) grants one event at a time over the
node's ``@replay`` queryable (`runtime.host.keys.KeyKind.REPLAY`): the gate
finds it among the core's `pending()` entries — waiting for it if it is still
in flight — sets the logical time, runs it with `NodeCore.run` and the grant's
`ctx.choose` answers, has the host perform the outputs, and answers with the
new state digest and what the handler published. The gate drives the core through its
public methods and observes it (`handled`) to learn what the handler did.

Wire protocol. A grant is a msgpack map naming the event (``kind``, ``handler``,
``sender``, ``args``: its `payload_digest`) with the logical time ``t`` and the
``choices`` that answer `ctx.choose`. The answer, sent once the handler ran and
its outputs were performed, is a msgpack map: ``digest`` (`state_digest` of the
new state), ``choices``, ``options``, ``error`` (or None) and ``published``
([topic, type] pairs). ``{"op": "status"}`` answers at once with the pending
events and the waiting grant.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, final

import msgpack

from twinfleet.runtime.contract.context import Publish
from twinfleet.runtime.contract.messages import type_name_of
from twinfleet.runtime.core.choosers import RecordingChooser
from twinfleet.runtime.core.eventlog import node_state_digest, payload_digest, summarise
from twinfleet.runtime.core.events import Event
from twinfleet.runtime.core.node_core import Handled, NodeCore
from twinfleet.runtime.core.outbox import Output
from twinfleet.runtime.host.clock import TimerHandle
from twinfleet.runtime.host.transport import Respond

GATED_CALL_WALL_S = 600.0  # a gated call waits for its grant, not for a timeout
_GRANT_KEYS = ("kind", "handler", "sender", "args", "t")


@final
class _NoTimer:
    def cancel(self) -> None:
        pass


@final
class LogicalClock:
    """The clock of a gated host: fleet time is the granted event's time; nothing fires by
    itself (timers wait in the core until granted; calls wait for their grant too)."""

    def __init__(self) -> None:
        self.now = 0

    def now_ms(self) -> int:
        """The logical time of the event being run (0 before the first grant)."""
        return self.now

    def call_at(self, due_ms: int, fn: Callable[..., Any], *args: Any) -> TimerHandle:
        """Never runs `fn`: a gated node's timed entries run when they are granted."""
        return _NoTimer()

    def real_seconds(self, fleet_ms: float) -> float:
        """Wall seconds a call may wait: long, since its reply waits for a grant."""
        return GATED_CALL_WALL_S


def describe(entry: Event) -> dict[str, Any]:
    """A pending entry as the coordinator's status request shows it."""
    return {"kind": str(entry.kind), "handler": entry.handler, "sender": entry.sender,
            "args": payload_digest(entry.args), "summary": summarise(entry.args)}


def matches(entry: Event, grant: dict[str, Any]) -> bool:
    """Whether `entry` is the event `grant` names (the argument digest is computed last)."""
    return (entry.handler == grant["handler"] and entry.kind == grant["kind"]
            and entry.sender == grant["sender"] and payload_digest(entry.args) == grant["args"])


@final
class ReplayGate:
    """Runs a gated node's pending events one grant at a time (module docstring).

    Args:
        core: the node core (built with ``keep_last=False``); the gate observes it.
        clock: the host's logical clock, set to each grant's time.
        perform: performs a handler's outputs (the host's).
    """

    def __init__(self, core: NodeCore, clock: LogicalClock,
                 perform: Callable[[Sequence[Output]], None]) -> None:
        self.core, self.clock, self.perform = core, clock, perform
        self.granted = 0
        self._grant: tuple[dict[str, Any], Respond] | None = None
        self._last: Handled | None = None
        core.observe(self)

    def handled(self, record: Handled) -> None:
        """Keep what the granted handler did (the core's `Observer` hook)."""
        self._last = record

    def poll(self) -> None:
        """Something new is pending: run the waiting grant if it names it."""
        if self._grant is not None:
            self._run()

    def on_request(self, payload: bytes, respond: Respond) -> None:
        """A grant or a status request from the coordinator."""
        try:
            grant = msgpack.unpackb(payload, raw=False)
            if grant.get("op") == "status":
                waiting = self._grant[0] if self._grant is not None else None
                respond(msgpack.packb({"ready": [describe(e) for e in self.core.pending()],
                                       "granted": self.granted, "waiting": waiting}), "")
                return
            missing = [k for k in _GRANT_KEYS if k not in grant]
            if missing:
                raise KeyError(", ".join(missing))
        except Exception as exc:  # a malformed grant is the coordinator's bug: say so
            respond(None, f"server error: bad grant ({exc!r})")
            return
        if self._grant is not None:
            respond(None, "server error: another grant is still waiting")
            return
        self._grant = (grant, respond)
        self._run()

    def _run(self) -> None:
        assert self._grant is not None
        grant, respond = self._grant
        entry = next((e for e in self.core.pending() if matches(e, grant)), None)
        if entry is None:
            return  # still in flight: `poll` tries again when something arrives
        self._grant = None
        self.clock.now = int(grant["t"])
        chooser = RecordingChooser(None, grant.get("choices") or ())
        self.perform(self.core.run(entry, self.clock.now, chooser))
        self.granted += 1
        record = self._last
        assert record is not None and record.entry is entry
        published = ([[e.topic, type_name_of(e.msg)] for e in record.effects if type(e) is Publish]
                     if record.error is None else [])
        respond(msgpack.packb({"digest": node_state_digest(self.core.node.state),
                               "choices": chooser.indices, "options": chooser.options,
                               "published": published,
                               "error": None if record.error is None else record.error.message}),
                "")
