"""ZenohTransport: the live `Transport`, one Zenoh session per process.

Thread boundary. Zenoh runs Python callbacks on its own threads. Every
callback here does one thing: append ``(fn, args)`` — plain bytes and strings,
or the `Query` object — to a deque, and schedule **one** drain on the asyncio
loop per burst (`call_soon_threadsafe` only when no drain is pending). The
drain runs the host's callbacks on the loop. No handler, decoding or session
method ever runs on a Zenoh thread.

Bounded hand-off. Samples wait in that deque only until the loop drains it;
if the loop stalls (a long handler, a suspended process), at most
``max_pending`` samples wait and later ones are dropped and counted
(``statistics().overflow``) rather than blocking Zenoh's thread. Queries,
replies and liveliness changes are never dropped (they are rare, and losing
one would hang a caller or hide a node). Per-subscription KEEP_LAST depth is
the node core's job, after decoding (see `runtime.core.node_core`).

Configuration. `zenoh_config` is the only place a Zenoh config is built: it
always disables multicast scouting and shared memory and enables timestamping
(needed by the advanced publisher of latched topics). The environment variable
``TWINFLEET_ZENOH_CONFIG_OVERRIDE='key=json5;key=json5'`` adjusts other keys
for every session of a fleet (the launcher's environment reaches its nodes),
e.g. ``transport/link/tx/lease=1000`` to notice a cut link within a second;
keys under ``scouting/multicast`` and ``transport/shared_memory`` are refused.

Guard (`runtime.core.guard`, README "Trust model"). With a fleet key, every put
and query carries a signature and a stamp (sender id, sequence number, role) as
its attachment, and a sample (or a service request) without a valid one is dropped
on Zenoh's thread before it is copied and counted (``statistics().refused``,
`Rejection.FORGED`); a sample above the payload limit is dropped first
(`Rejection.OVERSIZE`). A sample whose stamp was seen before is a replay
(`Rejection.REPLAYED`; on a latched subscription, where history and live copies
of one sample both arrive, the second copy is dropped uncounted); recorded input
(`Role.RECORDED`) passes only a transport made with ``accept_recorded``
(`Rejection.RECORDED` otherwise). These tests are cheaper than the hand-off they
spare a flood. With a bridge key as well, a sample on one of the `external`
keys that is signed with it instead is accepted and counted (``statistics().external``).

QoS mapping. Reliable topics publish with congestion control BLOCK,
best-effort ones with DROP. Transient-local ("latched") topics use
`zenoh.ext` advanced publishers (cache of `depth` samples, publisher
detection) and advanced subscribers (history with late-publisher detection),
so a late joiner receives the last samples.

Services. A queryable hands the `Query` to the loop; the host replies on the
queryable's key (or with `reply_err` "server error: ...") and the query is
finalised with ``with query:``, at once or, for a deferred reply, from a later
handler; a query still held when the transport closes is answered "server error".
A caller gets the first reply, or a `CallFailure` from what Zenoh reports: an
error reply from the server (`SERVER_ERROR`); the error reply ``Timeout`` Zenoh
itself gives when a server took the query and the timeout passed (`TIMEOUT`);
the query finalised with no reply at all, which is what Zenoh does when no
queryable took it or the one that did went away (`NO_SERVER`).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import traceback
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from typing import Any, final

import zenoh
from zenoh import ext

from twinfleet.runtime.contract.environment import EnvVar, env_value
from twinfleet.runtime.contract.messages import CallFailure
from twinfleet.runtime.contract.node import Durability, QoS, Reliability
from twinfleet.runtime.core.guard import ReplayWindow, Role, opened, signer
from twinfleet.runtime.core.statistics import Rejection
from twinfleet.runtime.host.transport import (
    Deliver,
    OnChange,
    OnDone,
    OnRequest,
    Respond,
    TransportStatistics,
)

OVERRIDE_ENV = EnvVar.ZENOH_CONFIG_OVERRIDE
_LOCKED = ("scouting/multicast", "transport/shared_memory")


def config_overrides(text: str | None = None) -> list[tuple[str, str]]:
    """Parse ``key=json5;key=json5`` (default: the `OVERRIDE_ENV` variable) into pairs.

    Raises:
        ValueError: on a malformed entry or a key that would re-enable multicast
            scouting or shared memory.
    """
    text = (env_value(OVERRIDE_ENV) or "") if text is None else text
    pairs = []
    for entry in filter(None, (e.strip() for e in text.split(";"))):
        key, sep, value = entry.partition("=")
        key = key.strip().strip("/")
        if not sep or not key or not value.strip():
            raise ValueError(f"{OVERRIDE_ENV}: expected key=value, got {entry!r}")
        if key.startswith(_LOCKED) or any(lock.startswith(key) for lock in _LOCKED):
            raise ValueError(f"{OVERRIDE_ENV}: {key} cannot be overridden "
                             "(multicast scouting and shared memory stay off)")
        pairs.append((key, value.strip()))
    return pairs


def zenoh_config(*, connect: Sequence[str] = (), listen: Sequence[str] = (),
                 mode: str = "client", settings: Mapping[str, Any] | None = None,
                 ) -> zenoh.Config:
    """Build a Zenoh config: loopback/explicit endpoints only, no multicast, no shared memory.

    Args:
        connect: endpoints to connect to, e.g. ``["tcp/127.0.0.1:7447"]``.
        listen: endpoints to listen on (routers and peers).
        mode: "client", "peer" or "router".
        settings: more keys (path → JSON value), e.g. a fleet's credentials and access
            control (`runtime.access.fleetauth`); applied before the override variable.

    Raises:
        ValueError: on a bad mode, or a bad ``TWINFLEET_ZENOH_CONFIG_OVERRIDE`` entry.
    """
    if mode not in ("client", "peer", "router"):
        raise ValueError(f"mode must be client, peer or router, got {mode!r}")
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")
    conf.insert_json5("transport/shared_memory/enabled", "false")
    conf.insert_json5("timestamping/enabled", "true")
    conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    for key, value in (settings or {}).items():
        conf.insert_json5(key, json.dumps(value))
    for key, value in config_overrides():
        try:
            conf.insert_json5(key, value)
        except zenoh.ZError as exc:
            raise ValueError(f"{OVERRIDE_ENV}: {key}={value}: {exc}") from None
    return conf


DEFAULT_MAX_PENDING = 20_000


class Handoff:
    """Coalesced hand-off of work from Zenoh threads to one asyncio loop.

    Args:
        loop: the loop that runs the queued calls.
        capacity: how many calls `offer` lets wait; `push` is not bounded.
    """

    def __init__(self, loop: asyncio.AbstractEventLoop, capacity: int = DEFAULT_MAX_PENDING,
                 ) -> None:
        self.loop = loop
        self.capacity = capacity
        self.pending: deque[tuple[Callable[..., Any], tuple[Any, ...]]] = deque()
        self.scheduled = False
        self.closed = False
        self.wakeups = 0
        self.overflow = 0
        self.after_drain: list[Callable[[], None]] = []

    def push(self, fn: Callable[..., Any], *args: Any) -> None:
        """Queue `fn(*args)` to run on the loop (any thread)."""
        if self.closed:
            return
        self.pending.append((fn, args))
        if not self.scheduled:  # after the append: a drain that already started sees it
            self._schedule()

    def _schedule(self) -> None:
        self.scheduled = True
        self.wakeups += 1
        try:
            self.loop.call_soon_threadsafe(self.drain)
        except RuntimeError:  # loop closed during shutdown
            self.closed = True

    def offer(self, fn: Callable[..., Any], *args: Any) -> bool:
        """Like `push`, but drop and count the call when `capacity` calls already wait."""
        pending = self.pending
        if len(pending) >= self.capacity:
            self.overflow += 1
            return False
        if not self.closed:  # `push`, inlined: this runs on Zenoh's thread for every sample
            pending.append((fn, args))
            if not self.scheduled:
                self._schedule()
        return True

    def drain(self) -> None:
        """Run every queued call, then the `after_drain` callbacks (on the loop)."""
        self.scheduled = False  # before popping: a push racing with us schedules again
        pending = self.pending
        while pending and not self.closed:
            fn, args = pending.popleft()
            fn(*args)
        for fn in self.after_drain:
            fn()


@final
class ZenohTransport:
    """`Transport` over one Zenoh session.

    Args:
        config: a config from `zenoh_config`.
        max_pending: samples allowed to wait for the loop before new ones are dropped.
        key: the fleet key (`runtime.core.guard`): sign what is published and queried, drop
            (and count as `Rejection.FORGED`) samples and requests without a valid tag.
        limit: payload bytes a sample may have (larger: dropped, counted as
            `Rejection.OVERSIZE`); `limits` sets it per key expression.
        bridge_key: the key a bridge to another system signs with (`runtime.core.guard`);
            accepted, with `key`, only on the keys in `external`.
        external: the data keys of the topics the node takes from outside the fleet.
        accept_recorded: let in samples signed as recorded input (``play --into-fleet``).
    """

    def __init__(self, config: zenoh.Config, *, max_pending: int = DEFAULT_MAX_PENDING,
                 key: bytes | None = None, limit: int | None = None,
                 limits: Mapping[str, int] | None = None, bridge_key: bytes | None = None,
                 external: frozenset[str] = frozenset(), accept_recorded: bool = False) -> None:
        self.config = config
        self.max_pending = max_pending
        self.key, self.limit, self.limits = key, limit, dict(limits or {})
        self.bridge_key, self.external = bridge_key, external
        self.accept_recorded = accept_recorded
        self._external = [0]  # a list: the sample callbacks count into it on Zenoh's thread
        self._refused = {Rejection.FORGED: 0, Rejection.OVERSIZE: 0, Rejection.REPLAYED: 0,
                         Rejection.RECORDED: 0}
        self._played = [0]  # one cell: Zenoh's threads add to it
        self._query_signers: dict[str, Callable[[bytes], bytes | None]] = {}
        self.session: zenoh.Session | None = None
        self._handoff: Handoff | None = None
        self._publishers: dict[str, Any] = {}
        self._advanced: list[Any] = []
        self._entities: list[Any] = []
        self._held: set[Respond] = set()  # queries taken and not answered yet

    @property
    def _s(self) -> zenoh.Session:
        if self.session is None:
            raise RuntimeError("ZenohTransport used before open()")
        return self.session

    @property
    def _h(self) -> Handoff:
        assert self._handoff is not None
        return self._handoff

    async def open(self) -> None:
        """Open the session (in a worker thread: connecting may take a moment)."""
        self._handoff = Handoff(asyncio.get_running_loop(), self.max_pending)
        self.session = await asyncio.to_thread(zenoh.open, self.config)

    async def __aenter__(self) -> ZenohTransport:
        await self.open()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    def subscribe(self, key: str, deliver: Deliver, qos: QoS) -> None:
        """Subscribe; latched QoS uses an advanced subscriber with history."""
        offer = self._h.offer
        latched = qos.durability is Durability.TRANSIENT_LOCAL
        if self.key is not None or self.limits.get(key, self.limit) is not None:
            on_sample = self._guarded(key, deliver, latched=latched)
        elif "*" in key:
            def on_sample(sample: zenoh.Sample) -> None:
                offer(deliver, str(sample.key_expr), sample.payload.to_bytes())
        else:  # a concrete key: every sample carries exactly this key
            def on_sample(sample: zenoh.Sample) -> None:
                offer(deliver, key, sample.payload.to_bytes())

        if latched:
            history = ext.HistoryConfig(detect_late_publishers=True, max_samples=max(1, qos.depth))
            self._advanced.append(ext.declare_advanced_subscriber(self._s, key, on_sample,
                                                                  history=history))
        else:
            self._entities.append(self._s.declare_subscriber(key, on_sample))

    def _guarded(self, key: str, deliver: Deliver, *,
                 latched: bool = False) -> Callable[[zenoh.Sample], None]:
        """A sample callback that refuses oversize, unsigned, replayed and (unless accepted)
        recorded samples before copying them.

        It runs on Zenoh's thread, as the plain callbacks do: a length test, one HMAC and
        one window update per sample, cheaper than the copy and hand-off it saves a flood.
        """
        offer, fleet_key, refused = self._h.offer, self.key, self._refused
        limit = self.limits.get(key, self.limit) or (1 << 62)
        bridge_key = self.bridge_key if key in self.external else None
        external = self._external
        window, accept_recorded, played = ReplayWindow(), self.accept_recorded, self._played

        def on_sample(sample: zenoh.Sample) -> None:
            if len(sample.payload) > limit:
                refused[Rejection.OVERSIZE] += 1
                return
            payload, where = sample.payload.to_bytes(), str(sample.key_expr)
            if fleet_key is not None:
                raw = sample.attachment.to_bytes() if sample.attachment else None
                stamp = opened(fleet_key, where, payload, raw)
                from_bridge = False
                if stamp is None and bridge_key is not None:
                    stamp = opened(bridge_key, where, payload, raw)
                    from_bridge = stamp is not None
                if stamp is None:
                    refused[Rejection.FORGED] += 1
                    return
                recorded = stamp.role is Role.RECORDED
                if recorded and not accept_recorded:
                    refused[Rejection.RECORDED] += 1
                    return
                if not window.fresh(where, stamp):
                    if not latched:  # there, the history's copy of a live sample
                        refused[Rejection.REPLAYED] += 1
                    return
                played[0] += recorded
                external[0] += from_bridge
            offer(deliver, where, payload)

        return on_sample

    def serve(self, key: str, on_request: OnRequest) -> None:
        """Declare a queryable; each query is answered on the loop and then finalised.

        With a fleet key, a request to a service without a valid tag is answered
        "server error: unauthenticated request" at once and counted as `Rejection.FORGED`.
        """
        push, refused, window = self._h.push, self._refused, ReplayWindow()
        # "@" queryables (statistics, types, info) are read-only views monitors may ask
        fleet_key = self.key if "/@" not in key else None

        def on_query(query: zenoh.Query) -> None:
            payload = query.payload.to_bytes() if query.payload is not None else b""
            if fleet_key is not None:
                tag = query.attachment
                stamp = opened(fleet_key, key, payload, tag.to_bytes() if tag else None)
                why = (Rejection.FORGED if stamp is None or stamp.role is not Role.MEMBER
                       else None if window.fresh(key, stamp) else Rejection.REPLAYED)
                if why is not None:
                    refused[why] += 1
                    push(self._refuse, query)
                    return
            push(self._answer, key, query, payload, on_request)

        self._entities.append(self._s.declare_queryable(key, on_query))

    @staticmethod
    def _refuse(query: zenoh.Query) -> None:
        with query:
            query.reply_err(b"server error: unauthenticated request (not signed with the "
                            b"fleet key, or a replay)")

    def _answer(self, key: str, query: zenoh.Query, payload: bytes,
                on_request: OnRequest) -> None:
        answered = False
        held = self._held

        def respond(reply: bytes | None, reason: str) -> None:
            nonlocal answered
            if answered:
                return
            answered = True
            held.discard(respond)
            with query:  # finalises the query: the caller does not wait for its timeout
                if reply is not None:
                    query.reply(key, reply)
                else:
                    query.reply_err(reason.encode())

        held.add(respond)  # until answered: a deferred reply comes from a later handler
        try:
            on_request(payload, respond)
        except Exception as exc:  # never leave a query unfinalised
            respond(None, f"server error: {exc}")
            traceback.print_exc()

    def put(self, key: str, payload: bytes, qos: QoS) -> None:
        """Publish through a per-key publisher declared on first use."""
        self.publisher(key, qos)(payload)

    def publisher(self, key: str, qos: QoS) -> Callable[[bytes], None]:
        """The `put` of the per-key publisher (declared on first use): no lookup per message."""
        pub = self._publishers.get(key)
        if pub is None:
            pub = self._declare_publisher(key, qos)
            self._publishers[key] = pub
        if self.key is None:
            return pub.put
        put, tag = pub.put, signer(self.key, key)
        return lambda payload: put(payload, attachment=tag(payload))

    def _declare_publisher(self, key: str, qos: QoS) -> Any:
        reliable = qos.reliability is Reliability.RELIABLE
        cc = zenoh.CongestionControl.BLOCK if reliable else zenoh.CongestionControl.DROP
        if qos.durability is Durability.TRANSIENT_LOCAL:
            pub = ext.declare_advanced_publisher(self._s, key, congestion_control=cc,
                                                 cache=ext.CacheConfig(max(1, qos.depth)),
                                                 publisher_detection=True)
            self._advanced.append(pub)
            return pub
        return self._s.declare_publisher(key, congestion_control=cc)

    def query(self, key: str, payload: bytes, timeout_ms: float, on_done: OnDone) -> None:
        """Query `key`; `on_done` gets the first reply, or None, the `CallFailure` Zenoh's
        answers tell (module docstring) and its words."""
        push = self._h.push
        state = {"done": False}
        timeout_s = timeout_ms / 1000.0

        def finish(reply: bytes | None, failure: CallFailure | None, reason: str) -> None:
            if not state["done"]:
                state["done"] = True
                on_done(reply, failure, reason)

        def on_reply(reply: zenoh.Reply) -> None:
            if reply.ok is not None:
                push(finish, reply.ok.payload.to_bytes(), None, "")
            elif reply.err is not None:
                text = reply.err.payload.to_string()
                if text == ZENOH_TIMEOUT:
                    push(finish, None, CallFailure.TIMEOUT, "timeout")
                else:
                    push(finish, None, CallFailure.SERVER_ERROR, _server_error(text))

        def on_final() -> None:  # after a reply or a timeout `finish` has run: no server
            push(finish, None, CallFailure.NO_SERVER, "no server")

        tag = self._query_signers.get(key)
        if tag is None:
            tag = self._query_signers[key] = signer(self.key, key)
        attachment = tag(payload)
        self._s.get(key, zenoh.handlers.Callback(on_reply, on_final), payload=payload,
                    timeout=timeout_s, attachment=attachment)

    def announce(self, token_key: str) -> None:
        """Declare a liveliness token."""
        self._entities.append(self._s.liveliness().declare_token(token_key))

    def watch(self, key_expr: str, on_change: OnChange) -> None:
        """Subscribe to liveliness changes, present tokens included."""
        push = self._h.push

        def on_sample(sample: zenoh.Sample) -> None:
            push(on_change, str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT)

        self._entities.append(self._s.liveliness().declare_subscriber(key_expr, on_sample,
                                                                      history=True))

    def after_burst(self, fn: Callable[[], None]) -> None:
        """Call `fn()` on the loop after each burst of deliveries has been handed over.

        The host runs its handlers there, in the same loop iteration as the burst
        (one loop iteration less per message than a `call_soon`).
        """
        self._h.after_drain.append(fn)

    def statistics(self) -> TransportStatistics:
        """Loop wake-ups used so far (one per burst), samples dropped by the bounded hand-off,
        samples and requests refused as forged or oversize, and samples taken with the
        bridge key."""
        h = self._handoff
        return TransportStatistics(wakeups=h.wakeups if h else 0,
                                   overflow=h.overflow if h else 0, refused=dict(self._refused),
                                   external=self._external[0], played=self._played[0])

    async def close(self) -> None:
        """Undeclare (advanced entities first), then close the session, on the loop thread."""
        if self._handoff is not None:
            self._handoff.closed = True
        for respond in list(self._held):  # a deferred reply that will never come
            respond(None, "server error: the server stopped before it replied")
        for entity in [*self._advanced, *self._publishers.values(), *self._entities]:
            with contextlib.suppress(Exception):  # already undeclared: nothing to do
                entity.undeclare()
        self._advanced.clear()
        self._publishers.clear()
        self._entities.clear()
        if self.session is not None and not self.session.is_closed():
            self.session.close()


#: the error reply Zenoh gives a query whose timeout passed after a queryable took it (our
#: servers' error replies all begin "server error", so it is never theirs)
ZENOH_TIMEOUT = "Timeout"


def _server_error(text: str) -> str:
    return text if text.startswith("server error") else f"server error: {text}"
