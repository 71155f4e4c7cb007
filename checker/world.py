"""Worlds: immutable snapshots of a whole fleet, and their time-shifted digests.

A `World` holds every node's state as snapshot bytes (unchanged nodes share
the same bytes object with their parent world, so nothing is re-encoded) and
the pending `Event`s in a canonical order. Its identity, `World.digest`, is a
16-byte BLAKE2b of a canonical encoding in which every due time is taken
relative to the *next* event time t* (time-shift equivalence, Timed Rebeca's
R9): two worlds that differ only by a constant offset of all pending times are
the same state, so periodic behaviour closes into finitely many states.
"""

from __future__ import annotations

import hashlib
from typing import Any, Final, final

import msgpack

from runtime.snapshot import snapshot

# Event kinds. Deliveries, requests and replies are *messages* (one FIFO
# channel per sender/receiver pair under `ros`); the rest are *timers*.
DELIVERY: Final = "delivery"
REQUEST: Final = "request"
REPLY: Final = "reply"
TIMER: Final = "timer"  # ctx.after, and the "no server" CallError of ctx.call
PERIODIC: Final = "periodic"
START: Final = "start"  # on_start handlers; only ever run while building initial worlds

MESSAGE_KINDS: Final = frozenset({DELIVERY, REQUEST, REPLY})

ENVIRONMENT: Final = -1  # sender index of events nobody sent


@final
class Event:
    """One pending handler run: `target.method(ctx, *args)` at time `due`.

    Attributes:
        due: absolute logical time (ms) at which the event is due.
        kind: one of DELIVERY, REQUEST, REPLY, TIMER, PERIODIC, START.
        target: index of the node that runs the handler.
        method: the handler's method name.
        sender: index of the node that caused the event (ENVIRONMENT if none).
        args: handler arguments after ctx (a message, or the args of ctx.after).
        priority: handler priority of `method` (lower runs first).
        reply_to: for requests, the caller's reply method; else "".
        rank: send order among pending events of the same channel and due time
            (always 0 under semantics that ignore send order).
        key: canonical encoding of everything above except `due` and `rank`.
    """

    __slots__ = ("args", "due", "key", "kind", "method", "priority", "rank", "reply_to",
                 "sender", "target")

    def __init__(self, due: int, kind: str, target: int, method: str, sender: int,
                 args: tuple[Any, ...], priority: int, reply_to: str = "", rank: int = 0,
                 key: bytes | None = None) -> None:
        self.due = due
        self.kind = kind
        self.target = target
        self.method = method
        self.sender = sender
        self.args = args
        self.priority = priority
        self.reply_to = reply_to
        self.rank = rank
        self.key = key if key is not None else event_key(kind, target, method, sender,
                                                         reply_to, args)

    @property
    def channel(self) -> tuple[int, int, bool]:
        """(sender, target, is_message): the FIFO channel of this event under `ros`."""
        return (self.sender, self.target, self.kind in MESSAGE_KINDS)

    def with_rank(self, rank: int) -> Event:
        """The same event with another rank."""
        return Event(self.due, self.kind, self.target, self.method, self.sender, self.args,
                     self.priority, self.reply_to, rank, self.key)

    def sort_key(self) -> tuple[int, bytes, int]:
        """Canonical order: due time, then the untimed encoding, then rank."""
        return (self.due, self.key, self.rank)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Event) and self.sort_key() == other.sort_key()

    def __hash__(self) -> int:
        return hash(self.sort_key())

    def __repr__(self) -> str:
        return (f"Event({self.kind} {self.sender}->{self.target}.{self.method} @{self.due}"
                f" prio={self.priority} rank={self.rank})")


@final
class World:
    """An immutable global state: node states, pending events, property monitors.

    Attributes:
        now: logical time of the event that produced this world (0 initially).
        states: per node (in scenario order) the snapshot bytes of its state.
        events: pending events, sorted by `Event.sort_key`.
        monitors: names of `within` properties not yet satisfied on this path.
        digest: 16-byte identity of the world up to time shift.
    """

    __slots__ = ("digest", "events", "monitors", "now", "states")

    def __init__(self, now: int, states: tuple[bytes, ...], events: tuple[Event, ...],
                 monitors: tuple[str, ...] = ()) -> None:
        self.now = now
        self.states = states
        self.events = events
        self.monitors = monitors
        self.digest = world_digest(states, events, monitors)

    @property
    def next_time(self) -> int | None:
        """t*: the due time of the earliest pending event (None if nothing is pending)."""
        return self.events[0].due if self.events else None

    @property
    def terminal(self) -> bool:
        """True when no event is pending (RMC's deadlock; our quiescence)."""
        return not self.events

    def __repr__(self) -> str:
        return f"World(now={self.now}, events={len(self.events)}, digest={self.digest.hex()[:12]})"


_HEADERS: dict[tuple[str, int, str, int, str], bytes] = {}
_NO_ARGS = snapshot(())


def event_key(kind: str, target: int, method: str, sender: int, reply_to: str,
              args: tuple[Any, ...]) -> bytes:
    """Canonical untimed encoding of an event: a cached header, then the encoded args.

    msgpack values are self-delimiting, so the concatenation is unambiguous.
    """
    head = (kind, target, method, sender, reply_to)
    header = _HEADERS.get(head)
    if header is None:
        header = _HEADERS[head] = snapshot(head)
    return header + (snapshot(args) if args else _NO_ARGS)


def world_digest(states: tuple[bytes, ...], events: tuple[Event, ...],
                 monitors: tuple[str, ...]) -> bytes:
    """The time-shifted identity of a world (see the module docstring).

    While a `within` monitor is pending the absolute t* is part of the identity,
    because the property's deadline is absolute; the monitor's bound keeps that finite.
    """
    base = events[0].due if events else 0
    timed = [(e.due - base, e.rank, e.key) for e in events]
    packed = msgpack.packb([list(states), timed, list(monitors), base if monitors else 0],
                           use_bin_type=True)
    return hashlib.blake2b(packed, digest_size=16).digest()


def sort_events(events: list[Event]) -> tuple[Event, ...]:
    """Events in canonical order."""
    events.sort(key=Event.sort_key)
    return tuple(events)
