"""The replay gate of a live node: only the events a replay coordinator grants run.

A gated node (``node_main --gate``) runs on a `LogicalClock` over a
`runtime.core.node_core.NodeCore` that holds every message it receives (no KEEP_LAST)
and every timer it arms; nothing runs by itself. The coordinator
(`twinfleet.agreement.live_replay`) grants one event at a time over the
node's ``@replay`` queryable (`runtime.host.keys.KeyKind.REPLAY`): the gate
finds it among the core's `pending()` entries — waiting for it if it is still
in flight — sets the logical time, runs it with `NodeCore.run` and the grant's
`ctx.choose` answers, has the host perform the outputs, and answers with the
new state digest, what the handler published and the digest of what it logged.
The gate drives the core through its public methods and observes it (`handled`)
to learn what the handler did.

Wire protocol: `runtime.host.replay_wire` (`Grant` in, `GrantAnswer` out, `STATUS`
answered with a `GateStatus`), the same values the coordinator imports.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, final

from twinfleet.runtime.contract.context import Log, Publish
from twinfleet.runtime.contract.messages import type_name_of
from twinfleet.runtime.core.choosers import RecordingChooser
from twinfleet.runtime.core.eventlog import node_state_digest
from twinfleet.runtime.core.node_core import Handled, NodeCore
from twinfleet.runtime.core.outbox import Output
from twinfleet.runtime.host.clock import TimerHandle
from twinfleet.runtime.host.replay_wire import (
    GateStatus,
    Grant,
    GrantAnswer,
    Held,
    WireError,
    is_status,
    logs_digest,
)
from twinfleet.runtime.host.transport import Respond

GATED_CALL_WALL_S = 600.0  # a gated call waits for its grant, not for a timeout


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
        self._grant: tuple[Grant, Respond] | None = None
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
        if is_status(payload):
            waiting = self._grant[0] if self._grant is not None else None
            status = GateStatus(tuple(Held.of(e) for e in self.core.pending()), self.granted,
                                waiting)
            respond(status.encode(), "")
            return
        try:
            grant = Grant.decode(payload)
        except WireError as exc:  # a malformed grant is the coordinator's bug: say so
            respond(None, f"server error: bad grant ({exc})")
            return
        if self._grant is not None:
            respond(None, "server error: another grant is still waiting")
            return
        self._grant = (grant, respond)
        self._run()

    def _run(self) -> None:
        assert self._grant is not None
        grant, respond = self._grant
        entry = next((e for e in self.core.pending() if grant.names(e)), None)
        if entry is None:
            return  # still in flight: `poll` tries again when something arrives
        self._grant = None
        self.clock.now = grant.t
        chooser = RecordingChooser(None, grant.choices)
        self.perform(self.core.run(entry, self.clock.now, chooser))
        self.granted += 1
        record = self._last
        assert record is not None and record.entry is entry
        published = (tuple((e.topic, type_name_of(e.msg)) for e in record.effects
                           if type(e) is Publish) if record.error is None else ())
        logs = [e for e in record.effects if type(e) is Log] if record.error is None else []
        answer = GrantAnswer(node_state_digest(self.core.node.state), tuple(chooser.indices),
                             tuple(chooser.options), published,
                             None if record.error is None else record.error.message,
                             logs_digest(logs))
        respond(answer.encode(), "")
