"""The live event log: every handler a node runs, as one flushed JSON line (an observer).

`EventLog` observes a `runtime.core.node_core.NodeCore` (``core.observe(log)``) and
writes one record per handler run: node, ``i`` (the record's index, from 0
per node), ``t`` (the time the handler saw), ``kind`` (an `EventKind`: start,
delivery, request, reply, timeout, timer, periodic, liveliness), handler,
sender, topic or service, the sender's ``seq`` and ``stamp``, ``due`` (timers,
ticks and call timeouts; for a start, when it was queued), ``args`` (the
`payload_digest` of the handler's arguments), ``summary``, the `ctx.choose`
answers (``choices``) with their option counts (``options``), ``digest`` (the
`state_digest` of the node's state after the handler: the same snapshot bytes
the checker keeps, so equal digests mean equal states) and ``error`` when
the handler failed. A ``timeout`` is a reply handler run with a `CallError`
(the call got no answer: timeout, no server, or a server error); ``reply``
is one run with the server's answer.

The first line of a file is a header (``kind: "header"``, ``format:``
`EVENTS_FORMAT`, the node and what the caller adds); a respawned node appends
a second header to the same file. `with_restarts` reads such a file as one
sequence: numbered on across the processes, each restart a ``crash`` record
(the checker's crash-and-restart) at the time of the new process's first event.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Final

import msgpack
import numpy as np

from twinfleet.runtime.contract.messages import to_plain
from twinfleet.runtime.contract.snapshot import snapshot

if TYPE_CHECKING:
    from twinfleet.runtime.core.node_core import Handled

EVENTS_FORMAT: Final = "twinfleet-events/2"


def state_digest(state: bytes) -> str:
    """Hex digest of a node state's snapshot bytes (`runtime.contract.snapshot.snapshot`).

    The checker keeps node states as the same snapshot bytes, so a live node
    and the checker agree on this digest exactly when their states are equal.
    """
    return hashlib.blake2b(state, digest_size=12).hexdigest()


def node_state_digest(state: Any) -> str:
    """`state_digest` of a live node's state, or why it has none (a node bug, reported)."""
    try:
        return state_digest(snapshot(state))
    except Exception as exc:  # the checker reports this too; the log says it
        return f"unsnapshotable: {exc}"


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


def with_restarts(records: Sequence[dict[str, Any]]) -> tuple[list[dict[str, Any]], int]:
    """One node's event records across its processes (module docstring) and how many
    restarts there were; header records are left out."""
    out: list[dict[str, Any]] = []
    headers = 0
    for rec in records:
        if rec.get("kind") == "header":
            headers += 1
            if headers > 1:
                out.append({"node": rec.get("node", ""), "kind": "crash", "handler": "",
                            "sender": "", "args": "", "digest": "", "t": None})
            continue
        if out and out[-1]["kind"] == "crash" and out[-1]["t"] is None:
            out[-1]["t"] = rec.get("t", 0)
        out.append(dict(rec))
    for i, rec in enumerate(out):
        rec["i"] = i
        if rec["t"] is None:  # a restart that logged nothing: at the last time known
            rec["t"] = out[i - 1]["t"] if i else 0
    return out, max(0, headers - 1)


class EventLog:
    """One node's handler runs as JSON lines, flushed one by one (module docstring).

    Args:
        path: the file, opened for appending.
        node: the node's name, for the header.
        header: more header fields (scenario, seed, time scale, ...).
    """

    def __init__(self, path: str, *, node: str, **header: Any) -> None:
        self.path = path
        self._file = open(path, "a", encoding="utf-8")  # noqa: SIM115 - closed by close()
        self.count = 0
        self._write({"format": EVENTS_FORMAT, "kind": "header", "node": node, **header})

    def _write(self, record: dict[str, Any]) -> None:
        self._file.write(json.dumps(record, separators=(",", ":")) + "\n")
        self._file.flush()

    def handled(self, record: Handled) -> None:
        """Log one handler run (the `runtime.core.node_core.Observer` hook)."""
        e = record.entry
        line = {"node": record.node.name, "t": record.now, "kind": str(e.kind),
                "handler": e.handler, "sender": e.sender, "topic": e.topic, "seq": e.seq,
                "stamp": e.stamp, "due": e.due, "args": payload_digest(e.args),
                "summary": summarise(e.args), "choices": list(record.choices),
                "options": list(record.options), "digest": node_state_digest(record.node.state)}
        if record.error is not None:
            line["error"] = record.error.message
        self.event(line)

    def event(self, record: dict[str, Any]) -> None:
        """Append one event record, numbering it (``i``, from 0 per node)."""
        record["i"] = self.count
        self.count += 1
        self._write(record)

    def close(self) -> None:
        """Close the file."""
        self._file.close()
