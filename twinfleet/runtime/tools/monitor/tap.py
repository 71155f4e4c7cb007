"""FleetTap: one Zenoh session that hears every topic of a fleet, for the viewer and the recorder.

It subscribes to ``twinfleet/<fleet>/**`` and, with an advanced subscriber
with history and late-publisher detection, to each latched topic, so a tap
that joins after a latched sample was published still receives it. The
latched topics are given, or added once known (`add_latched`: a viewer learns
them from the fleet's description, `runtime.host.keys.fleet_key`). A
latched sample then arrives on both subscribers; the tap passes it on once
(the same bytes again within 10 s are a copy, also when the live copy came
before the topic was known as latched; later, e.g. the next run's identical
map, they are a new sample). Samples cross from Zenoh's threads to the loop
through `Handoff` (one wake-up per burst) and reach `deliver(key, payload)` on
the loop, in arrival order.

Opening retries every 0.25 s when asked to (a viewer may start before the
fleet's router, or before any fleet is registered: `make_config` may raise
`LookupError` for "no endpoint yet"); the retried `zenoh.open` runs in a worker
thread and is never abandoned half-way, so no session is left open behind the
loop's back. A session that lost its router is replaced by a new one when
the config would now differ (`reopen_if_stale`): a fleet launched again on the
same endpoint has new credentials, which reconnecting never presents.
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import time
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any, final

import zenoh
from zenoh import ext

from twinfleet.runtime.access.fleetauth import MonitorAuth, login_settings, registry_auth
from twinfleet.runtime.host.keys import fleet_topics, topic_expr, topic_in_fleet
from twinfleet.runtime.host.zenoh_transport import Handoff, zenoh_config

RECONNECT = "{period_init_ms: 100, period_max_ms: 500, period_increase_factor: 1.5}"
RETRY_S = 0.25
FOLLOW_S = 1.0  # how often `follow_relaunches` looks at the link
DUPLICATE_WINDOW_S = 10.0  # history and live copies of one latched sample arrive well within
_SEEN_PER_KEY = 16

Deliver = Callable[[str, bytes], None]


def tap_config(endpoint: str, auth: MonitorAuth | None = None) -> zenoh.Config:
    """A client config for a tap on `endpoint` that reconnects within half a second when the
    router comes back (a fleet launched again on the same endpoint); zenoh's default back-off
    grows to seconds, and a viewer then missed the new run's first poses."""
    # the fleet's read-only login: given (--credentials), or a fleet launched on this machine
    settings = login_settings(auth if auth is not None else registry_auth(endpoint))
    conf = zenoh_config(connect=[endpoint], mode="client", settings=settings)
    conf.insert_json5("connect/retry", RECONNECT)
    return conf


@final
class FleetTap:
    """Every sample of a fleet, delivered on the asyncio loop.

    Args:
        make_config: builds the session's config (`runtime.host.zenoh_transport.zenoh_config`).
        fleet: fleet name, or ``*`` for every fleet on the router.
        deliver: called on the loop with (key, payload) for each sample.
        latched: fully qualified names of transient-local topics.
        retry: keep trying to open the session until the router answers.
    """

    def __init__(self, make_config: Callable[[], zenoh.Config], fleet: str, deliver: Deliver, *,
                 latched: Sequence[str] = (), retry: bool = True) -> None:
        self.make_config, self.fleet, self.deliver = make_config, fleet, deliver
        self.latched, self.retry = tuple(latched), retry
        self.session: zenoh.Session | None = None
        self.duplicates = 0
        self._entities: list[Any] = []
        self._advanced: list[Any] = []
        self._handoff: Handoff | None = None
        self._seen: dict[str, deque[tuple[bytes, float]]] = {}
        self._recent: dict[str, tuple[bytes, float]] = {}  # key → its last payload, arrival
        self._stopped = False
        self._config = ""  # the text of the config the session was opened with

    async def open(self, prepare: Callable[[zenoh.Session], object] | None = None) -> None:
        """Open the session (retrying if asked), then run `prepare(session)` in a thread if
        given (what must be known before the first sample arrives, such as the fleet's
        message schemas), then declare the subscribers."""
        while not self._stopped:
            try:
                config = self.make_config()
                self.session = await asyncio.to_thread(zenoh.open, config)
                self._config = str(config)
                break
            except (zenoh.ZError, LookupError):
                if not self.retry:
                    raise
                await asyncio.sleep(RETRY_S)
        if self._stopped or self.session is None:
            await self.close()
            return
        if prepare is not None:
            await asyncio.to_thread(prepare, self.session)
        self._handoff = Handoff(asyncio.get_running_loop())
        self._entities.append(self.session.declare_subscriber(
            fleet_topics(self.fleet), self._on_sample))
        for topic in self.latched:
            self._declare_latched(topic)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        """On a Zenoh thread: hand the sample to the loop."""
        handoff = self._handoff  # one read: a reopen may replace it meanwhile
        if handoff is not None:
            handoff.push(self._pass, str(sample.key_expr), sample.payload.to_bytes())

    def _declare_latched(self, topic: str) -> None:
        assert self.session is not None
        history = ext.HistoryConfig(detect_late_publishers=True, max_samples=1)
        self._advanced.append(ext.declare_advanced_subscriber(
            self.session, topic_expr(self.fleet, topic), self._on_sample, history=history))

    def add_latched(self, topics: Sequence[str]) -> None:
        """Treat `topics` as latched from now on (call on the loop): ask their history, and
        take a history copy of a sample already passed on for the copy it is."""
        for topic in topics:
            if topic in self.latched:
                continue
            self.latched = (*self.latched, topic)
            for key, (payload, when) in self._recent.items():
                where = topic_in_fleet(self.fleet, key)
                if where is not None and where.topic == topic:
                    self._remember(key, payload, when)
            if self.is_open:
                self._declare_latched(topic)

    def _remember(self, key: str, payload: bytes, when: float) -> None:
        digest = hashlib.blake2b(payload, digest_size=16).digest()
        self._seen.setdefault(key, deque(maxlen=_SEEN_PER_KEY)).append((digest, when))

    def _pass(self, key: str, payload: bytes) -> None:
        if not self._latched(key):
            self._recent[key] = (payload, time.monotonic())
        else:
            digest, now = hashlib.blake2b(payload, digest_size=16).digest(), time.monotonic()
            seen = self._seen.setdefault(key, deque(maxlen=_SEEN_PER_KEY))
            if any(d == digest and now - t < DUPLICATE_WINDOW_S for d, t in seen):
                self.duplicates += 1
                return
            seen.append((digest, now))
        self.deliver(key, payload)

    def _latched(self, key: str) -> bool:
        where = topic_in_fleet(self.fleet, key)
        return where is not None and where.topic in self.latched

    @property
    def is_open(self) -> bool:
        """True once the session is open and subscribed."""
        return self.session is not None and self._handoff is not None

    def routers(self) -> int:
        """How many routers the session reaches now (0 before it opens)."""
        if self.session is None or self.session.is_closed():
            return 0
        return len(list(self.session.info.routers_zid()))

    def stop(self) -> None:
        """Make a pending `open()` give up after its current attempt."""
        self._stopped = True

    async def reopen_if_stale(self) -> bool:
        """Open a new session when this one has lost its router and the config would now
        differ; True if it did. A fleet launched again on the same endpoint has new
        credentials (`runtime.access.fleetauth`), which the old session's reconnects never
        present, so without this a tap never saw the new run."""
        if self._stopped or not self.is_open or self.routers():
            return False
        try:
            fresh = str(await asyncio.to_thread(self.make_config))
        except (zenoh.ZError, LookupError):  # no fleet registered yet: nothing newer
            return False
        if fresh == self._config:
            return False
        await self._shut()
        await self.open()
        return True

    @property
    def stopped(self) -> bool:
        """True once `stop` or `close` was called."""
        return self._stopped

    async def close(self) -> None:
        """Undeclare (advanced subscribers first), then close the session, on the loop thread."""
        self._stopped = True
        await self._shut()

    async def _shut(self) -> None:
        """`close` without stopping: the session and its subscribers go, `open` may follow."""
        if self._handoff is not None:
            self._handoff.drain()  # what already arrived still counts
            self._handoff.closed = True
        for entity in [*self._advanced, *self._entities]:
            with contextlib.suppress(Exception):  # already gone with the session
                entity.undeclare()
        self._advanced.clear()
        self._entities.clear()
        if self.session is not None and not self.session.is_closed():
            self.session.close()
        self.session, self._handoff = None, None


async def follow_relaunches(tap: FleetTap, period_s: float = FOLLOW_S) -> None:
    """Keep `tap` on its fleet until cancelled: every `period_s`, a session that lost its
    router is replaced when the fleet was launched again with new credentials
    (`FleetTap.reopen_if_stale`; `make_config` must read them afresh, e.g. from the
    registry), and a tap whose reopening failed (no router yet) tries again."""
    while not tap.stopped:
        await asyncio.sleep(period_s)
        try:
            if tap.is_open:
                await tap.reopen_if_stale()
            elif not tap.stopped:
                await tap.open()
        except (zenoh.ZError, LookupError):  # the new run's router is not up yet
            continue
