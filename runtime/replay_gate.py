"""Event log and replay gate of a live node host (issue 6).

With an `EventLog`, a `NodeHost` writes every dispatched event as one flushed
JSON line: node, handler, kind (start, timer, after, delivery, request,
reply, liveliness), sender, topic or service, the sender's seq and stamp, the
due time of timers, the dispatch time, a digest of the arguments
(`payload_digest`), the `ctx.choose` answers with their option counts, and
the digest of the node's state after the handler (`state_digest`: the same
snapshot bytes the checker keeps, so equal digests mean equal states).

With a `ReplayGate` (and a `LogicalClock`), nothing runs by itself: every
ready event, timers included, waits until a replay coordinator
(`agreement.live_replay`) grants it over the queryable `gate_key(fleet,
node)`, with the logical time and the `ctx.choose` answers to use; the reply
reports the state digest and the publications.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, final

import msgpack
import numpy as np

from twinfleet.runtime.clock import TimerHandle
from twinfleet.runtime.context import Chooser, Publish
from twinfleet.runtime.messages import (
    to_plain,
    type_name_of,
)
from twinfleet.runtime.names import KEY_PREFIX
from twinfleet.runtime.snapshot import snapshot
from twinfleet.runtime.transport import Respond

if TYPE_CHECKING:
    from twinfleet.runtime.host import NodeHost

EVENTS_FORMAT = "twinfleet-events/1"
GATED_CALL_WALL_S = 600.0  # a gated call waits for its grant, not for a timeout


def state_digest(state: bytes) -> str:
    """Hex digest of a node state's snapshot bytes (`runtime.snapshot.snapshot`).

    The checker keeps node states as the same snapshot bytes, so a live node
    and the checker agree on this digest exactly when their states are equal.
    """
    return hashlib.blake2b(state, digest_size=12).hexdigest()


def _digestible(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, set | frozenset):
        return sorted(value, key=repr)
    return repr(value)


def payload_digest(args: Sequence[Any]) -> str:
    """Hex digest of a handler's arguments, blind to tuple/list and numpy/int differences.

    A message decoded from the wire and the same message built by the checker's
    run of the sending handler give the same digest.
    """
    packed = msgpack.packb(to_plain(list(args)), default=_digestible, use_bin_type=True)
    return hashlib.blake2b(packed, digest_size=8).hexdigest()


def summarise(args: Sequence[Any], limit: int = 160) -> str:
    """A short human-readable form of handler arguments, for logs and reports."""
    text = ", ".join(repr(a) for a in args)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def gate_key(fleet: str, node: str) -> str:
    """Key of a gated node's replay queryable (an `@` chunk: data subscribers never see it)."""
    return f"{KEY_PREFIX}/{fleet}/@replay/{node}"


@final
class RecordingChooser:
    """Answers `ctx.choose` with `forced` indices first, then from `inner` (or 0), and
    records every answer and how many options it had (the checker's `Step.choices/options`)."""

    __slots__ = ("forced", "indices", "inner", "options")

    def __init__(self, inner: Chooser | None, forced: Sequence[int] = ()) -> None:
        self.inner, self.forced = inner, tuple(forced)
        self.indices: list[int] = []
        self.options: list[int] = []

    def choose(self, n: int) -> int:
        """The forced index of this choice point, else `inner`'s answer, else 0."""
        k = len(self.indices)
        if k < len(self.forced):
            index = self.forced[k]
        else:
            index = self.inner.choose(n) if self.inner is not None else 0
        self.indices.append(index)
        self.options.append(n)
        if not 0 <= index < n:
            raise ValueError(f"choice point {k} has {n} options, cannot answer {index}")
        return index


@final
class _NoTimer:
    def cancel(self) -> None:
        pass


@final
class LogicalClock:
    """The clock of a gated host: fleet time is the granted event's time; nothing fires by
    itself (timers wait in the gate, call timeouts never fire: calls wait for their grant)."""

    def __init__(self) -> None:
        self.now = 0

    def now_ms(self) -> int:
        """The logical time of the event being run (0 before the first grant)."""
        return self.now

    def call_at(self, due_ms: int, fn: Callable[..., Any], *args: Any) -> TimerHandle:
        """Never runs `fn`: a gated host holds its timers in the `ReplayGate` instead."""
        return _NoTimer()

    def real_seconds(self, fleet_ms: float) -> float:
        """Wall seconds a call may wait: long, since its reply waits for a grant."""
        return GATED_CALL_WALL_S


@final
class EventLog:
    """One node's dispatched events as JSON lines, flushed one by one (module docstring).

    The first line is a header (``kind: "header"``, the format and `header`);
    a respawned node appends a second header to the same file.
    """

    def __init__(self, path: str, *, node: str, **header: Any) -> None:
        self.path = path
        self._file = open(path, "a", encoding="utf-8")  # noqa: SIM115 - closed by close()
        self.count = 0
        self._write({"format": EVENTS_FORMAT, "kind": "header", "node": node, **header})

    def _write(self, record: dict[str, Any]) -> None:
        self._file.write(json.dumps(record, separators=(",", ":")) + "\n")
        self._file.flush()

    def event(self, record: dict[str, Any]) -> None:
        """Append one event record, numbering it (``i``, from 0 per node)."""
        record["i"] = self.count
        self.count += 1
        self._write(record)

    def close(self) -> None:
        """Close the file."""
        self._file.close()


# An event's description, kept only when events are logged or gated:
# (kind, sender, topic or service, seq, stamp_ms, due_ms).
EventMeta = tuple[str, str, str, int, int | None, int | None]


@final
class ReadyEvent:
    """One event a gated host holds until it is granted."""

    __slots__ = ("_digest", "args", "meta", "method", "respond")

    def __init__(self, method: str, args: tuple[Any, ...], respond: Respond | None,
                 meta: EventMeta) -> None:
        self.method, self.args, self.respond, self.meta = method, args, respond, meta
        self._digest: str | None = None

    def digest(self) -> str:
        if self._digest is None:
            self._digest = payload_digest(self.args)
        return self._digest

    def matches(self, grant: dict[str, Any]) -> bool:
        return (self.method == grant["handler"] and self.meta[0] == grant["kind"]
                and self.meta[1] == grant["sender"] and self.digest() == grant["args"])

    def describe(self) -> dict[str, Any]:
        return {"kind": self.meta[0], "handler": self.method, "sender": self.meta[1],
                "args": self.digest(), "summary": summarise(self.args)}


@final
class ReplayGate:
    """Holds a gated host's ready events and runs only the one a coordinator grants.

    A grant is a msgpack map naming the event (``kind``, ``handler``, ``sender``,
    ``args``: its `payload_digest`) with the logical time ``t`` and the
    ``choices`` that answer `ctx.choose`. If no ready event matches yet (a
    message still in flight) the grant waits for it. The answer, sent once the
    handler ran and its effects were performed, is a msgpack map: ``digest``
    (`state_digest` of the new state), ``choices``, ``options``, ``error``
    (or None) and ``published`` ([topic, type] pairs). ``{"op": "status"}``
    answers at once with the ready events and the waiting grant.
    """

    def __init__(self, host: NodeHost) -> None:
        self.host = host
        self.ready: list[ReadyEvent] = []
        self.granted = 0
        self._grant: tuple[dict[str, Any], Respond] | None = None

    def add(self, item: ReadyEvent) -> None:
        """A new ready event; run it at once if it is the one the waiting grant names."""
        self.ready.append(item)
        if self._grant is not None:
            self._run()

    def on_request(self, payload: bytes, respond: Respond) -> None:
        """A grant or a status request from the coordinator."""
        try:
            grant = msgpack.unpackb(payload, raw=False)
            if grant.get("op") == "status":
                waiting = self._grant[0] if self._grant is not None else None
                respond(msgpack.packb({"ready": [r.describe() for r in self.ready],
                                       "granted": self.granted, "waiting": waiting}), "")
                return
            missing = [k for k in ("kind", "handler", "sender", "args", "t") if k not in grant]
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
        item = next((r for r in self.ready if r.matches(grant)), None)
        if item is None:
            return
        self._grant = None
        self.ready.remove(item)
        host = self.host
        assert isinstance(host.clock, LogicalClock)
        host.clock.now = int(grant["t"])
        chooser = RecordingChooser(None, grant.get("choices") or ())
        effects, error = host._dispatch(item.method, item.args, item.respond, item.meta, chooser)
        self.granted += 1
        if item.meta[0] == "timer":  # re-arm a periodic timer only once it has run
            spec = host.spec.by_method(item.method)
            if spec is not None and item.meta[5] is not None:
                host._arm_every(spec, item.meta[5] + host.node.period_ms(spec))
        try:
            digest = state_digest(snapshot(host.node.state))
        except Exception as exc:  # an unsnapshotable state is a node bug: report it
            digest = f"unsnapshotable: {exc}"
        published = [[e.topic, type_name_of(e.msg)] for e in effects
                     if type(e) is Publish] if error is None else []
        respond(msgpack.packb({"digest": digest, "choices": chooser.indices,
                               "options": chooser.options, "published": published,
                               "error": None if error is None else error.message}), "")
