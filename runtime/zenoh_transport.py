"""ZenohTransport: the live `Transport`, one Zenoh session per process.

Thread boundary. Zenoh runs Python callbacks on its own threads. Every
callback here does one thing: append ``(fn, args)`` — plain bytes and strings,
or the `Query` object — to a deque, and schedule **one** drain on the asyncio
loop per burst (`call_soon_threadsafe` only when no drain is pending). The
drain runs the host's callbacks on the loop. No handler, decoding or session
method ever runs on a Zenoh thread.

Configuration. `zenoh_config` is the only place a Zenoh config is built: it
always disables multicast scouting and shared memory and enables timestamping
(needed by the advanced publisher of latched topics).

QoS mapping. Reliable topics publish with congestion control BLOCK,
best-effort ones with DROP. Transient-local ("latched") topics use
`zenoh.ext` advanced publishers (cache of `depth` samples, publisher
detection) and advanced subscribers (history with late-publisher detection),
so a late joiner receives the last samples.

Services. A queryable hands the `Query` to the loop; the host replies on the
queryable's key (or with `reply_err` "server error: ...") and the query is
finalised with ``with query:``. A caller gets the first reply, or, when the
query is finalised with no reply, "no server" (finalised early) or "timeout".
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
import traceback
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any, final

import zenoh
from zenoh import ext

from runtime.node import Durability, QoS, Reliability
from runtime.transport import Deliver, OnChange, OnDone, OnRequest


def zenoh_config(*, connect: Sequence[str] = (), listen: Sequence[str] = (),
                 mode: str = "client") -> zenoh.Config:
    """Build a Zenoh config: loopback/explicit endpoints only, no multicast, no shared memory.

    Args:
        connect: endpoints to connect to, e.g. ``["tcp/127.0.0.1:7447"]``.
        listen: endpoints to listen on (routers and peers).
        mode: "client", "peer" or "router".
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
    return conf


class Handoff:
    """Coalesced hand-off of work from Zenoh threads to one asyncio loop."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self.loop = loop
        self.pending: deque[tuple[Callable[..., Any], tuple[Any, ...]]] = deque()
        self.scheduled = False
        self.closed = False
        self.wakeups = 0

    def push(self, fn: Callable[..., Any], *args: Any) -> None:
        """Queue `fn(*args)` to run on the loop (any thread)."""
        if self.closed:
            return
        self.pending.append((fn, args))
        if not self.scheduled:
            self.scheduled = True
            self.wakeups += 1
            try:
                self.loop.call_soon_threadsafe(self.drain)
            except RuntimeError:  # loop closed during shutdown
                self.closed = True

    def drain(self) -> None:
        """Run every queued call (on the loop)."""
        self.scheduled = False  # before popping: a push racing with us schedules again
        pending = self.pending
        while pending and not self.closed:
            fn, args = pending.popleft()
            fn(*args)


@final
class ZenohTransport:
    """`Transport` over one Zenoh session.

    Args:
        config: a config from `zenoh_config`.
    """

    def __init__(self, config: zenoh.Config) -> None:
        self.config = config
        self.session: zenoh.Session | None = None
        self._handoff: Handoff | None = None
        self._publishers: dict[str, Any] = {}
        self._advanced: list[Any] = []
        self._entities: list[Any] = []

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
        self._handoff = Handoff(asyncio.get_running_loop())
        self.session = await asyncio.to_thread(zenoh.open, self.config)

    async def __aenter__(self) -> ZenohTransport:
        await self.open()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    def subscribe(self, key: str, deliver: Deliver, qos: QoS) -> None:
        """Subscribe; latched QoS uses an advanced subscriber with history."""
        push = self._h.push

        def on_sample(sample: zenoh.Sample) -> None:
            push(deliver, str(sample.key_expr), sample.payload.to_bytes())

        if qos.durability is Durability.TRANSIENT_LOCAL:
            history = ext.HistoryConfig(detect_late_publishers=True, max_samples=max(1, qos.depth))
            self._advanced.append(ext.declare_advanced_subscriber(self._s, key, on_sample,
                                                                  history=history))
        else:
            self._entities.append(self._s.declare_subscriber(key, on_sample))

    def serve(self, key: str, on_request: OnRequest) -> None:
        """Declare a queryable; each query is answered on the loop and then finalised."""
        push = self._h.push

        def on_query(query: zenoh.Query) -> None:
            payload = query.payload.to_bytes() if query.payload is not None else b""
            push(self._answer, key, query, payload, on_request)

        self._entities.append(self._s.declare_queryable(key, on_query))

    @staticmethod
    def _answer(key: str, query: zenoh.Query, payload: bytes, on_request: OnRequest) -> None:
        answered = False

        def respond(reply: bytes | None, reason: str) -> None:
            nonlocal answered
            if answered:
                return
            answered = True
            with query:  # finalises the query: the caller does not wait for its timeout
                if reply is not None:
                    query.reply(key, reply)
                else:
                    query.reply_err(reason.encode())

        try:
            on_request(payload, respond)
        except Exception as exc:  # never leave a query unfinalised
            respond(None, f"server error: {exc}")
            traceback.print_exc()

    def put(self, key: str, payload: bytes, qos: QoS) -> None:
        """Publish through a per-key publisher declared on first use."""
        pub = self._publishers.get(key)
        if pub is None:
            pub = self._declare_publisher(key, qos)
            self._publishers[key] = pub
        pub.put(payload)

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
        """Query `key`; `on_done` gets the first reply, or None and a reason."""
        push = self._h.push
        state = {"done": False}
        started = time.monotonic()
        timeout_s = timeout_ms / 1000.0

        def finish(reply: bytes | None, reason: str) -> None:
            if not state["done"]:
                state["done"] = True
                on_done(reply, reason)

        def on_reply(reply: zenoh.Reply) -> None:
            if reply.ok is not None:
                push(finish, reply.ok.payload.to_bytes(), "")
            elif reply.err is not None:
                text = reply.err.payload.to_string()
                push(finish, None, "timeout" if text == "Timeout" else _server_error(text))

        def on_final() -> None:
            elapsed = time.monotonic() - started
            push(finish, None, "timeout" if elapsed >= 0.9 * timeout_s else "no server")

        self._s.get(key, zenoh.handlers.Callback(on_reply, on_final), payload=payload,
                    timeout=timeout_s)

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

    def statistics(self) -> dict[str, int]:
        """Loop wake-ups used so far (one per burst of samples)."""
        return {"wakeups": self._handoff.wakeups if self._handoff else 0}

    async def close(self) -> None:
        """Undeclare (advanced entities first), then close the session, on the loop thread."""
        if self._handoff is not None:
            self._handoff.closed = True
        for entity in [*self._advanced, *self._publishers.values(), *self._entities]:
            with contextlib.suppress(Exception):  # already undeclared: nothing to do
                entity.undeclare()
        self._advanced.clear()
        self._publishers.clear()
        self._entities.clear()
        if self.session is not None and not self.session.is_closed():
            self.session.close()


def _server_error(text: str) -> str:
    return text if text.startswith("server error") else f"server error: {text}"
