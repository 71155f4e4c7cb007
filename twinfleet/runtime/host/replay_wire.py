"""The live replay's wire protocol, imported by both ends: the coordinator
(`twinfleet.agreement.live_replay`) and the gate of each gated node
(`runtime.host.replay_gate`).

A `Grant` names one event a gated node holds (its kind, handler, sender and the
`payload_digest` of its arguments) with the logical time to run it at and the answers to
its `ctx.choose` calls; the node runs it and answers with a `GrantAnswer`: the new state
digest, the choices it made among which options, what it published, the digest of what it
logged (`logs_digest`, which the coordinator computes from the checker's run of the same
step) and its error. A
`STATUS` request is answered at once with a `GateStatus`: what the node holds and the
grant still waiting for its event. Each travels as one msgpack map; `decode` refuses a
map that lacks a field with `WireError`, naming it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Final, final

import msgpack

from twinfleet.runtime.contract.context import Log
from twinfleet.runtime.contract.kinds import EventKind
from twinfleet.runtime.core.eventlog import payload_digest, summarise
from twinfleet.runtime.core.events import Event

#: the request that asks a gate for its `GateStatus`
STATUS: Final = msgpack.packb({"op": "status"})


class WireError(ValueError):
    """A replay message that is not one: the text names what is missing or wrong."""


def _map(payload: bytes, what: str, keys: tuple[str, ...]) -> Mapping[str, Any]:
    try:
        doc = msgpack.unpackb(payload, raw=False)
    except Exception as exc:  # msgpack raises several unrelated types
        raise WireError(f"{what}: not msgpack ({exc!r})") from None
    if not isinstance(doc, dict):
        raise WireError(f"{what}: expected a map, got {type(doc).__name__}")
    missing = [k for k in keys if k not in doc]
    if missing:
        raise WireError(f"{what}: missing {', '.join(missing)}")
    return doc


def logs_digest(logs: Sequence[Log]) -> str:
    """The digest of a handler's `ctx.log` records, the same for the live node and the
    checker's run of the same step (`payload_digest` over (event, fields) pairs)."""
    return payload_digest(tuple((log.event, log.fields) for log in logs))


def is_status(payload: bytes) -> bool:
    """Whether `payload` is the `STATUS` request."""
    return payload == STATUS


@final
@dataclass(frozen=True, slots=True)
class Grant:
    """One event a coordinator lets a gated node run."""

    kind: EventKind
    handler: str
    sender: str
    args: str  # `payload_digest` of the event's arguments
    t: int  # the logical time to run it at
    choices: tuple[int, ...] = ()  # the answers to the handler's `ctx.choose` calls
    step: int = 0  # the trace step it replays (for messages)

    def names(self, entry: Event) -> bool:
        """Whether `entry` is the event this grant names (the argument digest last)."""
        return (entry.handler == self.handler and entry.kind == self.kind
                and entry.sender == self.sender and payload_digest(entry.args) == self.args)

    def encode(self) -> bytes:
        """The grant as it travels."""
        return msgpack.packb({"step": self.step, "kind": self.kind.value,
                              "handler": self.handler, "sender": self.sender,
                              "args": self.args, "t": self.t, "choices": list(self.choices)})

    @classmethod
    def decode(cls, payload: bytes) -> Grant:
        """A grant from the wire; `WireError` for anything else."""
        doc = _map(payload, "grant", ("kind", "handler", "sender", "args", "t"))
        try:
            return cls(EventKind(doc["kind"]), str(doc["handler"]), str(doc["sender"]),
                       str(doc["args"]), int(doc["t"]), tuple(map(int, doc.get("choices") or ())),
                       int(doc.get("step", 0)))
        except (TypeError, ValueError) as exc:
            raise WireError(f"grant: {exc}") from None


@final
@dataclass(frozen=True, slots=True)
class GrantAnswer:
    """What a gated node reports once a granted handler ran and its outputs went out."""

    digest: str  # `node_state_digest` of the new state
    choices: tuple[int, ...]  # the indices `ctx.choose` returned
    options: tuple[int, ...]  # how many options each `ctx.choose` had
    published: tuple[tuple[str, str], ...] = ()  # (topic, message type) per publication
    error: str | None = None  # the handler's failure, if it failed
    logs: str = ""  # `logs_digest` of what the handler logged

    def encode(self) -> bytes:
        """The answer as it travels."""
        return msgpack.packb({"digest": self.digest, "choices": list(self.choices),
                              "options": list(self.options),
                              "published": [list(p) for p in self.published],
                              "error": self.error, "logs": self.logs})

    @classmethod
    def decode(cls, payload: bytes) -> GrantAnswer:
        """An answer from the wire; `WireError` for anything else."""
        doc = _map(payload, "grant answer", ("digest", "choices", "options"))
        try:
            return cls(str(doc["digest"]), tuple(map(int, doc["choices"])),
                       tuple(map(int, doc["options"])),
                       tuple((str(t), str(m)) for t, m in doc.get("published") or ()),
                       None if doc.get("error") is None else str(doc["error"]),
                       str(doc.get("logs", "")))
        except (TypeError, ValueError) as exc:
            raise WireError(f"grant answer: {exc}") from None


@final
@dataclass(frozen=True, slots=True)
class Held:
    """One event a gated node holds, as a status shows it."""

    kind: str
    handler: str
    sender: str
    args: str  # `payload_digest` of its arguments
    summary: str  # its arguments, shortened for people

    @classmethod
    def of(cls, entry: Event) -> Held:
        """How a status shows `entry`."""
        return cls(str(entry.kind), entry.handler, entry.sender, payload_digest(entry.args),
                   summarise(entry.args))


@final
@dataclass(frozen=True, slots=True)
class GateStatus:
    """A gate's answer to `STATUS`: what it holds, how many grants ran, the waiting one."""

    ready: tuple[Held, ...]
    granted: int
    waiting: Grant | None

    def encode(self) -> bytes:
        """The status as it travels."""
        held = [[h.kind, h.handler, h.sender, h.args, h.summary] for h in self.ready]
        waiting = None if self.waiting is None else self.waiting.encode()
        return msgpack.packb({"ready": held, "granted": self.granted, "waiting": waiting})

    @classmethod
    def decode(cls, payload: bytes) -> GateStatus:
        """A status from the wire; `WireError` for anything else."""
        doc = _map(payload, "gate status", ("ready", "granted", "waiting"))
        try:
            ready = tuple(Held(*map(str, h)) for h in doc["ready"])
            waiting = None if doc["waiting"] is None else Grant.decode(doc["waiting"])
            return cls(ready, int(doc["granted"]), waiting)
        except (TypeError, ValueError) as exc:
            raise WireError(f"gate status: {exc}") from None
