"""State reports: what each live node tells the launcher's monitor after a handler.

A `StateReporter` is an observer of the node core (`runtime.core.node_core.Observer`),
like the event log. After each handler it snapshots the node's state
(`runtime.contract.snapshot`, the bytes the checker stores) and, when the state
changed or the handler failed (it raised, or called ``ctx.fail``), publishes
one `StateReport` through the `put` it was given: the node process publishes
them on its fleet-internal ``@state`` key (`runtime.host.keys.KeyKind.STATE`;
reliable, congestion control BLOCK). A handler that changed nothing and
failed nothing costs one snapshot and one bytes comparison. With
``states=False`` (no property reads the node) only failures are reported.

Wire format: a msgpack array ``[seq, now_ms, kind, handler, sender, topic,
failure, state, breach]``; ``seq`` counts reports from 1 (a gap is a lost report),
``failure`` is the failure's text or nil, ``state`` the snapshot bytes or nil
when unchanged, ``breach`` true when the failure is a breach of the node contract
(the handler raised `ContractError`: the checker answers no verdict then, and
neither does the launcher). The launcher's side is `runtime.fleet.live_verdict`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, final

import msgpack

from twinfleet.runtime.contract.context import Fail
from twinfleet.runtime.contract.snapshot import snapshot
from twinfleet.runtime.core.node_core import Handled

_PACK = msgpack.Packer(use_bin_type=True).pack  # one packer: `packb` builds one per call


@final
@dataclass(frozen=True, slots=True)
class StateReport:
    """One report: which handler ran (the causing event), whether it failed, the new state."""

    node: str
    seq: int
    now_ms: int
    kind: str
    handler: str
    sender: str
    topic: str
    failure: str | None
    state: bytes | None  # snapshot bytes; None: unchanged
    breach: bool = False  # the failure breaks the node contract (`ContractError`)

    def event(self) -> str:
        """The causing event in words, e.g. ``delivery on /poses from r2 → map_server.on_pose``."""
        source = f" on {self.topic}" if self.topic else ""
        sender = f" from {self.sender}" if self.sender and self.sender != self.node else ""
        return f"{self.kind}{source}{sender} → {self.node}.{self.handler}"


def encode_report(seq: int, record: Handled, failure: str | None, state: bytes | None) -> bytes:
    """The wire form of a report on `record` (module docstring)."""
    e = record.entry
    breach = record.error is not None and record.error.contract
    return _PACK([seq, record.now, e.kind.value, e.handler, e.sender, e.topic, failure, state,
                  breach])


def decode_report(node: str, payload: bytes) -> StateReport:
    """A report read from the wire.

    Raises:
        ValueError: the payload is not a state report.
    """
    try:
        seq, now, kind, handler, sender, topic, failure, state, breach = \
            msgpack.unpackb(payload, raw=False)
    except Exception as exc:  # msgpack's errors, or the wrong shape
        raise ValueError(f"not a state report: {exc}") from None
    return StateReport(node, int(seq), int(now), str(kind), str(handler), str(sender),
                       str(topic), failure, state, bool(breach))


def _failure(record: Handled) -> str | None:
    if record.error is not None:
        fix = f"; fix: {record.error.fix}" if record.error.contract and record.error.fix else ""
        return f"{record.error}{fix}"
    reasons = [e.reason for e in record.effects if type(e) is Fail]
    return f"{record.node.name}.{record.entry.handler}: ctx.fail({'; '.join(reasons)})" \
        if reasons else None


@final
class StateReporter:
    """Publishes a node's state after each handler that changed it or failed (module docstring).

    Args:
        node: the node whose state is reported.
        put: publishes one payload on the node's ``@state`` key.
        states: report states (False: only failures).
    """

    def __init__(self, node: Any, put: Callable[[bytes], None], *, states: bool = True) -> None:
        self._put, self._states = put, states
        self._last = snapshot(node.state) if states else b""
        self._seq = 0
        self.reports = 0

    def handled(self, record: Handled) -> None:
        """After a handler: publish a report if the state changed or the handler failed."""
        failure = _failure(record)
        state = None
        if self._states:
            try:
                data = snapshot(record.node.state)
            except Exception as exc:  # SnapshotError: a state the checker could not store either
                data, failure = self._last, failure or f"{record.node.name}: state: {exc}"
            if data != self._last:
                state = self._last = data
        if state is None and failure is None:
            return
        self._seq += 1
        self._put(encode_report(self._seq, record, failure, state))
        self.reports += 1
