"""Building worlds: canonical event order, `within` obligations, and the search key.

A `System` builds every world through one `WorldBuilder`. Node states arrive
interned (`checker.runner`), so the builder hashes each distinct node state
once and keys a world by its parts' 64-bit content hashes (`World.key`,
`checker.world.fast_key`); with `exact` it keys worlds by their 128-bit digest
instead. Worlds carry the `within` obligations still pending on their path
(`checker.properties.PropertySet.update`).
"""

from __future__ import annotations

import hashlib
from typing import TYPE_CHECKING, final

from twinfleet.checker.world import Event, World, joined_key, sort_events, world_digest

if TYPE_CHECKING:
    from twinfleet.checker.properties import PropertySet, States

_HASH_LIMIT = 100_000  # node-state content hashes kept before starting afresh


@final
class WorldBuilder:
    """Builds the worlds of one system.

    Args:
        reader: what property expressions read node states through (the system).
        properties: the properties whose `within` obligations worlds carry, or None.
        exact: key worlds by their 128-bit digest (`World.digest`).
        keyed: key worlds as they are built; off, a world's key is computed if it is
            read (a simulation follows one path and never looks a world up).
        ranked: events may have ranks other than 0 (semantics that keep send order).
    """

    def __init__(self, reader: States, properties: PropertySet | None, *, exact: bool,
                 keyed: bool = True, ranked: bool = True) -> None:
        self.reader = reader
        self.properties = properties
        self.exact = exact
        self.keyed = keyed
        # Only `within` obligations are carried: without any, every world carries none
        self._within = properties is not None and bool(properties.within)
        self.ranked = ranked
        self._hashes: dict[bytes, bytes] = {}
        # the node hashes of a tuple of node states, joined: most steps change no node's
        # state, and a tuple of the same (interned) states is found by identity
        self._joined: dict[tuple[bytes, ...], bytes] = {}
        self.hashed = 0  # node-state content hashes computed: for the collision bound

    def __len__(self) -> int:
        return len(self._hashes)

    def world(self, now: int, states: tuple[bytes, ...], pending: list[Event],
              parent: World | None, crashes: int = 0) -> World:
        """The world with node `states` and `pending` events at `now`, after `parent`."""
        events = sort_events(pending, _appended(pending, parent, crashes))
        obligations: tuple[str, ...] = ()
        if self._within:
            assert self.properties is not None
            obligations = self.properties.update(self.reader, parent, now, states, events)
        if not self.keyed:
            return World(now, states, events, obligations, crashes=crashes)
        if self.exact:
            digest = world_digest(states, events, obligations, crashes)
            return World(now, states, events, obligations, crashes=crashes, key=digest,
                         digest=digest)
        joined = self._joined.get(states) or self._join(states)  # never b"": a node or more
        return World(now, states, events, obligations, crashes=crashes,
                     key=joined_key(joined, events, obligations, crashes, ranked=self.ranked))

    def _join(self, states: tuple[bytes, ...]) -> bytes:
        if len(self._joined) >= _HASH_LIMIT:
            self._joined.clear()
        hashes = self._hashes
        joined = self._joined[states] = b"".join([hashes.get(s) or self._hash_state(s)
                                                  for s in states])  # a digest is never b""
        return joined

    def _hash_state(self, data: bytes) -> bytes:
        if len(self._hashes) >= _HASH_LIMIT:
            self._hashes.clear()
        h = self._hashes[data] = hashlib.blake2b(data, digest_size=8).digest()
        self.hashed += 1
        return h


def _appended(pending: list[Event], parent: World | None, crashes: int) -> int | None:
    """How many events a step appended to `pending` after its parent's others, which are
    in canonical order: a step takes one event of its world and appends what it sent (a
    KEEP_LAST drop, nothing; `checker.system`), so a world with its parent's crash count
    has one event fewer than its parent before them. None (sort them all): an initial
    world, or a crash fault, which drops all of a node's events and counts one crash more."""
    if parent is None or crashes != parent.crashes:
        return None
    return len(pending) - len(parent.events) + 1
