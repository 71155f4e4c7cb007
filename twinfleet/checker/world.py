"""Worlds: immutable snapshots of a whole fleet, and their time-shifted identities.

A `World` holds every node's state as snapshot bytes (unchanged nodes share
the same bytes object with their parent world, and `checker.system` interns
equal states to one object, so nothing is re-encoded or stored twice) and the
pending `Event`s in a canonical order. Identity is always up to time shift:
every due time is taken relative to the *next* event time t* (Timed Rebeca's
R9), so two worlds that differ only by a constant offset of all pending times
are the same state and periodic behaviour closes into finitely many states.

A world has two identities with the same meaning:

- `World.key`, what the search stores: by default a 64-bit BLAKE2b over the
  node states' and events' own 64-bit content hashes (computed once per
  distinct node state / event, see `fast_key`), so building a world hashes a
  few hundred bytes however large the node states are. Two different worlds
  share a key with probability about n²/2^65 for n stored worlds (the search
  prints the estimate, as TLC does).
- `World.digest`, 16 bytes of BLAKE2b over the full canonical encoding
  (`world_digest`), computed on first use. Traces and replay compare it, and
  `--exact-states` uses it as the key (then a false merge needs a 128-bit
  collision).

Beyond node states and due times the identity holds the `within` obligations
still pending, the crash count when crash faults are on, and, per event,
whether it will miss its deadline (see `Event.late`).
"""

from __future__ import annotations

import functools
import hashlib
import struct
from bisect import insort
from collections.abc import Callable, Iterable
from operator import attrgetter
from typing import Any, Final, final

import msgpack

from twinfleet.runtime.contract.kinds import EventKind
from twinfleet.runtime.contract.snapshot import snapshot

ENVIRONMENT: Final = -1  # sender index of events nobody sent

# `EventKind.is_message` as a tuple: `in` finds a member by identity, with no Python-level
# enum hash (Events are built in the search's inner loop).
_MESSAGE_KINDS: Final = tuple(k for k in EventKind if k.is_message)


@final
class Event:
    """One pending handler run: `target.method(ctx, *args)` at time `due`.

    Deliveries, requests and replies are *messages* (`EventKind.is_message`: one
    FIFO channel per sender/receiver pair under `ros`); timers, periodic timers
    and call timeouts are a node's own. START events only run while building
    initial worlds (and restarts); CRASH only labels crash transitions, it is
    never pending.

    Attributes:
        due: absolute logical time (ms) at which the event is due.
        kind: what made the handler run (a call's timeout is TIMEOUT).
        target: index of the node that runs the handler.
        method: the handler's method name.
        sender: index of the node that caused the event (ENVIRONMENT if none).
        args: handler arguments after ctx (a message, or the args of ctx.after).
        priority: handler priority of `method` (lower runs first).
        reply_to: for requests, the caller's reply method; else "".
        rank: send order among pending events of the same channel and due time
            (always 0 under semantics that ignore send order).
        key: canonical encoding of everything above except `due` and `rank`.
        deadline: absolute time by which a message must be handled, or None.
        sk: the canonical sort key (due, key, rank, late).
        message: `kind.is_message`, kept (the enabling rules read it in their inner loops).
    """

    __slots__ = ("_ident", "args", "deadline", "due", "key", "kind", "message", "method",
                 "priority", "rank", "reply_to", "sender", "sk", "target")

    def __init__(self, due: int, kind: EventKind, target: int, method: str, sender: int,
                 args: tuple[Any, ...], priority: int, reply_to: str = "", rank: int = 0,
                 key: bytes | None = None, deadline: int | None = None) -> None:
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
        self.deadline = deadline
        self.sk = (due, self.key, rank, deadline is not None and due > deadline)
        self.message = kind in _MESSAGE_KINDS
        self._ident: bytes | None = None

    @property
    def channel(self) -> tuple[int, int, bool]:
        """(sender, target, is_message): the FIFO channel of this event under `ros`."""
        return (self.sender, self.target, self.message)

    @property
    def late(self) -> bool:
        """True when the event is due after its deadline (it will be a deadline miss).

        Due times never change once an event is pending (time only passes when
        nothing is due), so lateness is decided when the event is added; it is
        the only part of the deadline that can change what happens next.
        """
        return self.sk[3]

    def moved(self, due: int, rank: int) -> Event:
        """The same event with another due time and rank (FIFO clamping, renumbering)."""
        ev = Event(due, self.kind, self.target, self.method, self.sender, self.args,
                   self.priority, self.reply_to, rank, self.key, self.deadline)
        if due == self.due:
            ev._ident = self._ident
        return ev

    def with_rank(self, rank: int) -> Event:
        """The same event with another rank."""
        return self.moved(self.due, rank)

    def ident(self) -> bytes:
        """8-byte content hash of the untimed identity (key and lateness), cached."""
        if self._ident is None:
            data = self.key + b"\x01" if self.sk[3] else self.key
            self._ident = hashlib.blake2b(data, digest_size=8).digest()
        return self._ident

    def sort_key(self) -> tuple[int, bytes, int, bool]:
        """Canonical order: due time, then the untimed encoding, rank, lateness."""
        return self.sk

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Event) and self.sk == other.sk

    def __hash__(self) -> int:
        return hash(self.sk)

    def __repr__(self) -> str:
        return (f"Event({self.kind} {self.sender}->{self.target}.{self.method} @{self.due}"
                f" prio={self.priority} rank={self.rank})")

    def __getstate__(self) -> tuple[Any, ...]:
        return (self.due, self.kind, self.target, self.method, self.sender, self.args,
                self.priority, self.reply_to, self.rank, self.key, self.deadline)

    def __setstate__(self, state: tuple[Any, ...]) -> None:
        self.__init__(*state)


@final
class World:
    """An immutable global state: node states, pending events, open `within` obligations.

    Attributes:
        now: logical time of the event that produced this world (0 initially).
        states: per node (in scenario order) the snapshot bytes of its state.
        events: pending events, sorted by `Event.sort_key`.
        obligations: names of `within` properties not yet satisfied on this path.
        crashes: crash faults injected on the path to this world.
        key: the identity the search stores (see the module docstring).
    """

    __slots__ = ("_digest", "_key", "crashes", "events", "obligations", "now", "states")

    def __init__(self, now: int, states: tuple[bytes, ...], events: tuple[Event, ...],
                 obligations: tuple[str, ...] = (), *, crashes: int = 0,
                 key: int | bytes | None = None, digest: bytes | None = None) -> None:
        self.now = now
        self.states = states
        self.events = events
        self.obligations = obligations
        self.crashes = crashes
        self._digest = digest
        self._key = key

    @property
    def key(self) -> int | bytes:
        """The identity the search stores (computed on first use when not given: a
        simulation never reads it)."""
        key = self._key
        if key is None:
            hashes = [hashlib.blake2b(s, digest_size=8).digest() for s in self.states]
            key = self._key = fast_key(hashes, self.events, self.obligations, self.crashes)
        return key

    @property
    def digest(self) -> bytes:
        """16-byte identity over the full canonical encoding (computed on first use)."""
        if self._digest is None:
            self._digest = world_digest(self.states, self.events, self.obligations, self.crashes)
        return self._digest

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

    def __getstate__(self) -> tuple[Any, ...]:
        return (self.now, self.states, self.events, self.obligations, self.crashes, self.key)

    def __setstate__(self, state: tuple[Any, ...]) -> None:
        self.now, self.states, self.events, self.obligations, self.crashes, self._key = state
        self._digest = None


_NO_ARGS = snapshot(())


@functools.lru_cache(maxsize=1 << 16)
def _header(kind: EventKind, target: int, method: str, sender: int, reply_to: str) -> bytes:
    # Bounded: one process may build many systems (a sweep, a test session), and a system
    # has a few hundred distinct headers at most.
    return snapshot((kind.value, target, method, sender, reply_to))


def earliest_time(worlds: Iterable[World]) -> int | None:
    """The smallest t* of `worlds` (None if nothing is pending in any): cached handler
    outcomes of events due before it serve none of them."""
    return min((t for w in worlds if (t := w.next_time) is not None), default=None)


def event_key(kind: EventKind, target: int, method: str, sender: int, reply_to: str,
              args: tuple[Any, ...]) -> bytes:
    """Canonical untimed encoding of an event: a cached header, then the encoded args.

    msgpack values are self-delimiting, so the concatenation is unambiguous. The kind
    is encoded as its string value (what traces and logs show).
    """
    return _header(kind, target, method, sender, reply_to) + (snapshot(args) if args else _NO_ARGS)


def world_digest(states: tuple[bytes, ...], events: tuple[Event, ...],
                 obligations: tuple[str, ...], crashes: int = 0) -> bytes:
    """The exact (128-bit) time-shifted identity of a world (see the module docstring).

    While a `within` monitor is pending the absolute t* is part of the identity,
    because the property's deadline is absolute; the monitor's bound keeps that finite.
    """
    base = events[0].due if events else 0
    timed = [(e.due - base, e.rank, e.key, True) if e.sk[3] else (e.due - base, e.rank, e.key)
             for e in events]
    doc: list[Any] = [list(states), timed, list(obligations), base if obligations else 0]
    if crashes:
        doc.append(crashes)
    packed = msgpack.packb(doc, use_bin_type=True)
    return hashlib.blake2b(packed, digest_size=16).digest()


def fast_key(state_hashes: list[bytes], events: tuple[Event, ...], obligations: tuple[str, ...],
             crashes: int = 0) -> int:
    """The 64-bit search key of a world from its node states' 8-byte content hashes.

    Layout hashed: node hashes, event hashes (canonical order), then int64s
    [len(events), crashes, t* if obligations else 0, due offsets..., ranks...],
    then the monitor names. Fixed-width parts make the layout unambiguous.
    """
    return joined_key(b"".join(state_hashes), events, obligations, crashes)


def joined_key(state_hashes: bytes, events: tuple[Event, ...], obligations: tuple[str, ...],
               crashes: int = 0, *, ranked: bool = True) -> int:
    """`fast_key` from its node hashes already joined (a builder keeps them by node states:
    most steps change no node's state); `ranked` False: every event's rank is 0 (semantics
    that ignore send order), which saves reading them."""
    n = len(events)
    base = events[0].due if n else 0
    pack = _PACKERS.get(n) or _packer(n)
    try:  # an event's hash is computed once, when a key first needs it
        idents = b"".join(map(_IDENT, events))
    except TypeError:
        idents = b"".join([e._ident or e.ident() for e in events])
    ranks = [e.rank for e in events] if ranked else _ZEROS.get(n) or _zeros(n)
    data = state_hashes + idents + pack(n, crashes, base if obligations else 0,
                                         *[e.due - base for e in events], *ranks)
    if obligations:
        data += "\0".join(obligations).encode()
    return int.from_bytes(hashlib.blake2b(data, digest_size=8).digest(), "little")


_IDENT = attrgetter("_ident")
_ZEROS: dict[int, tuple[int, ...]] = {}


def _zeros(n: int) -> tuple[int, ...]:
    zeros = _ZEROS[n] = (0,) * n
    return zeros


# `fast_key`'s int64s packed by one prepared struct per event count (native byte order,
# as the array("q") the layout was first written with: the same keys, checkpoints stay
# readable), which packs them without building a list first.
_PACKERS: dict[int, Callable[..., bytes]] = {}


def _packer(n: int) -> Callable[..., bytes]:
    pack = _PACKERS[n] = struct.Struct(f"={3 + 2 * n}q").pack
    return pack


_SK = attrgetter("sk")


def sort_events(events: list[Event], appended: int | None = None) -> tuple[Event, ...]:
    """Events in canonical order; `appended`: only the last so many of `events` may be out
    of it (a step's new events after its world's others), each then goes where a stable
    sort would put it, without sorting the rest again."""
    if appended is None or not 0 <= appended <= _INSERTED:
        events.sort(key=_SK)
    elif appended:
        tail = events[-appended:]
        del events[-appended:]
        for ev in tail:
            insort(events, ev, key=_SK)
    return tuple(events)


# More appended events than this are sorted with the rest (binary insertion pays for few).
_INSERTED: Final = 4
