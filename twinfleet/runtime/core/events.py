"""`Event`: one event waiting to run on a live node, named by its `EventKind`.

The live form of the concept the checker calls `checker.world.Event` too: the same kind,
handler, arguments and sender, with what a live node needs besides (sequence number,
stamp, the way back to a caller); the checker's carries what identifies a world instead.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from twinfleet.runtime.contract.kinds import EventKind


@dataclass(frozen=True, slots=True, eq=False)  # identity: two equal messages are two events
class Event:
    """What runs (kind, handler, args) and where it came from.

    Attributes:
        kind: what made the handler run.
        handler: the node's method name.
        args: the handler's arguments after `ctx` (the message, request, reply, ...).
        sender: the node that sent it (the node itself for its timers, starts and CallErrors).
        topic: the topic or service it came on ("" for timers and starts).
        seq: the sender's sequence number on that topic (0 when there is none).
        stamp: the sender's fleet ms when it sent it (None for local events).
        due: the fleet ms a timed entry is due (TIMER, PERIODIC, TIMEOUT; START: when it
            was queued); None for events that arrive.
        call: a TIMEOUT entry's call id: void once that call got an answer.
        responder: a REQUEST's call (`ReplyToken`) and its way back to its caller, opaque
            to the core.
    """

    kind: EventKind
    handler: str
    args: tuple[Any, ...] = ()
    sender: str = ""
    topic: str = ""
    seq: int = 0
    stamp: int | None = None
    due: int | None = None
    call: int | None = None
    responder: Any = field(default=None, repr=False)
