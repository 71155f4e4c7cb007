"""The byte transport under `NodeHost`, and an in-memory implementation for tests.

`Transport` is the narrow seam between the host and the network: put bytes on
a key, subscribe to a key, serve and query a key, declare and watch liveliness
tokens. Every callback a transport invokes (`deliver`, `on_request`,
`on_done`, `on_change`) runs **on the asyncio loop**, never on a network
thread. `ZenohTransport` (twinfleet/runtime/host/zenoh_transport.py) is the live one;
`LoopbackTransport` connects transports of one process through a shared
`LoopbackBus`, with the same asynchronous delivery (nothing is delivered
inside the call that sent it).

Graph keys (liveliness tokens, `runtime.host.keys.node_key`) let monitors find
the fleet without any registry.
"""

from __future__ import annotations

import asyncio
import functools
import itertools
from collections import defaultdict, deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Protocol, final

from twinfleet.runtime.contract.messages import CallFailure
from twinfleet.runtime.contract.node import Durability, QoS
from twinfleet.runtime.core.statistics import Rejection

Deliver = Callable[[str, bytes], None]
Respond = Callable[[bytes | None, str], None]  # (reply payload, "") or (None, error reason)
OnRequest = Callable[[bytes, Respond], None]
#: a query's end: the reply payload, or None with what failed and why in words
OnDone = Callable[[bytes | None, CallFailure | None, str], None]
OnChange = Callable[[str, bool], None]  # token key, alive

@final
@dataclass(frozen=True, slots=True)
class TransportStatistics:
    """A transport's counters since it opened.

    Attributes:
        wakeups: loop wake-ups used to hand samples over (one per burst).
        overflow: samples a bounded hand-off to the loop dropped (the loop fell behind).
        refused: samples and requests refused before decoding, per reason (a live
            transport counts `Rejection.FORGED`, `Rejection.OVERSIZE`,
            `Rejection.REPLAYED` and `Rejection.RECORDED`).
        external: samples accepted with the bridge key instead of the fleet key.
        played: recorded samples let in (signed as `runtime.core.guard.Role.RECORDED`).
    """

    wakeups: int = 0
    overflow: int = 0
    refused: Mapping[Rejection, int] = field(default_factory=dict)
    external: int = 0
    played: int = 0



class Transport(Protocol):
    """What `NodeHost` needs from a network. All callbacks run on the asyncio loop."""

    async def open(self) -> None:
        """Connect; must be awaited on the loop that will run the callbacks."""
        ...

    def subscribe(self, key: str, deliver: Deliver, qos: QoS) -> None:
        """Call `deliver(key, payload)` for each sample on `key` (latched QoS gets history)."""
        ...

    def serve(self, key: str, on_request: OnRequest) -> None:
        """Call `on_request(payload, respond)` per query; `respond` must be called once."""
        ...

    def put(self, key: str, payload: bytes, qos: QoS) -> None:
        """Publish `payload` on `key` (reliable → never dropped silently; latched → cached)."""
        ...

    def publisher(self, key: str, qos: QoS) -> Callable[[bytes], None]:
        """A function that puts a payload on `key`, as `put(key, payload, qos)` does.

        The host fetches one per topic, so a publish costs no per-message key lookup.
        """
        ...

    def query(self, key: str, payload: bytes, timeout_ms: float, on_done: OnDone) -> None:
        """Ask the server of `key`; `on_done` runs once: the reply, or None, the
        `CallFailure` and its words."""
        ...

    def announce(self, token_key: str) -> None:
        """Declare a liveliness token that lives as long as the transport."""
        ...

    def watch(self, key_expr: str, on_change: OnChange) -> None:
        """Call `on_change(key, alive)` for present and future liveliness tokens."""
        ...

    async def close(self) -> None:
        """Undeclare everything and disconnect."""
        ...

    def statistics(self) -> TransportStatistics:
        """The transport's counters (`TransportStatistics`)."""
        ...


def key_matches(pattern: str, key: str) -> bool:
    """Whether a concrete `key` matches `pattern` with Zenoh's `*` and `**` wildcards."""
    return _match(pattern.split("/"), key.split("/"))


def _match(pat: list[str], key: list[str]) -> bool:
    if not pat:
        return not key
    head = pat[0]
    if head == "**":
        return any(_match(pat[1:], key[i:]) for i in range(len(key) + 1)
                   if all(not k.startswith("@") for k in key[:i]))
    if not key:
        return False
    if head == "*":
        return not key[0].startswith("@") and _match(pat[1:], key[1:])
    return head == key[0] and _match(pat[1:], key[1:])


@dataclass
class LoopbackBus:
    """The shared medium of `LoopbackTransport`s: subscribers, servers, tokens, latched caches."""

    subscribers: list[tuple[LoopbackTransport, str, Deliver, QoS]] = field(default_factory=list)
    servers: list[tuple[LoopbackTransport, str, OnRequest]] = field(default_factory=list)
    tokens: dict[str, LoopbackTransport] = field(default_factory=dict)
    watchers: list[tuple[LoopbackTransport, str, OnChange]] = field(default_factory=list)
    latched: dict[str, deque[bytes]] = field(default_factory=dict)


@final
class LoopbackTransport:
    """In-process transport over a `LoopbackBus`; deliveries are scheduled with `call_soon`."""

    _ids = itertools.count()

    def __init__(self, bus: LoopbackBus | None = None) -> None:
        self.bus = bus if bus is not None else LoopbackBus()
        self.id = next(self._ids)
        self._loop: asyncio.AbstractEventLoop | None = None
        self.sent: defaultdict[str, int] = defaultdict(int)

    @property
    def loop(self) -> asyncio.AbstractEventLoop:
        """The loop callbacks run on (set by `open`)."""
        if self._loop is None:
            raise RuntimeError("LoopbackTransport used before open()")
        return self._loop

    async def open(self) -> None:
        """Bind to the running loop."""
        self._loop = asyncio.get_running_loop()

    def subscribe(self, key: str, deliver: Deliver, qos: QoS) -> None:
        """Register a subscriber; latched subscriptions receive the cached samples first."""
        self.bus.subscribers.append((self, key, deliver, qos))
        if qos.durability is Durability.TRANSIENT_LOCAL:
            for cached_key, samples in self.bus.latched.items():
                if key_matches(key, cached_key):
                    for payload in list(samples)[-qos.depth:]:
                        self.loop.call_soon(deliver, cached_key, payload)

    def serve(self, key: str, on_request: OnRequest) -> None:
        """Register a server for `key`."""
        self.bus.servers.append((self, key, on_request))

    def put(self, key: str, payload: bytes, qos: QoS) -> None:
        """Deliver `payload` to every matching subscriber on the next loop iterations."""
        self.sent[key] += 1
        if qos.durability is Durability.TRANSIENT_LOCAL:
            self.bus.latched.setdefault(key, deque(maxlen=max(1, qos.depth))).append(payload)
        for _, pattern, deliver, _ in list(self.bus.subscribers):
            if key_matches(pattern, key):
                self.loop.call_soon(deliver, key, payload)

    def publisher(self, key: str, qos: QoS) -> Callable[[bytes], None]:
        """`put` on `key` with `qos`, as a one-argument function."""
        return functools.partial(self.put, key, qos=qos)

    def query(self, key: str, payload: bytes, timeout_ms: float, on_done: OnDone) -> None:
        """Send a request to the first matching server; time out after `timeout_ms` wall ms."""
        servers = [s for s in self.bus.servers if key_matches(s[1], key)]
        done = False

        def finish(reply: bytes | None, failure: CallFailure | None, reason: str) -> None:
            nonlocal done
            if not done:
                done = True
                on_done(reply, failure, reason)

        if not servers:
            self.loop.call_soon(finish, None, CallFailure.NO_SERVER, "no server")
            return
        self.loop.call_later(timeout_ms / 1000.0, finish, None, CallFailure.TIMEOUT, "timeout")

        def respond(reply: bytes | None, reason: str) -> None:
            failure = None if reply is not None else CallFailure.SERVER_ERROR
            self.loop.call_soon(finish, reply, failure, reason)

        self.loop.call_soon(servers[0][2], payload, respond)

    def announce(self, token_key: str) -> None:
        """Declare a token and tell matching watchers."""
        self.bus.tokens[token_key] = self
        for _, pattern, on_change in list(self.bus.watchers):
            if key_matches(pattern, token_key):
                self.loop.call_soon(on_change, token_key, True)

    def watch(self, key_expr: str, on_change: OnChange) -> None:
        """Watch tokens matching `key_expr`, present ones included."""
        self.bus.watchers.append((self, key_expr, on_change))
        for token in sorted(self.bus.tokens):
            if key_matches(key_expr, token):
                self.loop.call_soon(on_change, token, True)

    def statistics(self) -> TransportStatistics:
        """Delivery is unbounded in memory and unsigned: nothing is ever dropped or refused."""
        return TransportStatistics()

    async def close(self) -> None:
        """Remove this transport's entities; its tokens disappear for the watchers."""
        bus = self.bus
        bus.subscribers = [s for s in bus.subscribers if s[0] is not self]
        bus.servers = [s for s in bus.servers if s[0] is not self]
        bus.watchers = [w for w in bus.watchers if w[0] is not self]
        gone = sorted(k for k, owner in bus.tokens.items() if owner is self)
        for token in gone:
            del bus.tokens[token]
            for owner, pattern, on_change in list(bus.watchers):
                if key_matches(pattern, token):
                    owner.loop.call_soon(on_change, token, False)
