"""One set of expectations, run over LoopbackTransport and ZenohTransport (real Zenoh, 127.0.0.1)."""

from __future__ import annotations

import asyncio
import threading
from collections.abc import AsyncIterator, Callable, Coroutine, Iterator
from contextlib import asynccontextmanager
from typing import Any

import pytest

from twinfleet.runtime.contract.messages import CallFailure
from twinfleet.runtime.contract.node import QOS_DEFAULT, QOS_LATCHED
from twinfleet.runtime.host.keys import KeyKind, kind_expr, node_key
from twinfleet.runtime.host.transport import (
    LoopbackBus,
    LoopbackTransport,
    Transport,
    key_matches,
)

zenoh = pytest.importorskip("zenoh")

from twinfleet.runtime.fleet.launcher import free_port  # noqa: E402
from twinfleet.runtime.host.zenoh_transport import ZenohTransport, zenoh_config  # noqa: E402

KEY = "twinfleet/conf/topic"


@pytest.fixture(scope="module")
def router() -> Iterator[str]:
    """An in-process Zenoh router on a free loopback port."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    session = zenoh.open(zenoh_config(listen=[endpoint], mode="router"))
    try:
        yield endpoint
    finally:
        session.close()


Factory = Callable[[], Coroutine[Any, Any, Transport]]


@pytest.fixture(params=["loopback", pytest.param("zenoh", marks=pytest.mark.fleet)])
def make(request: pytest.FixtureRequest) -> Factory:
    """A factory of opened transports that can talk to each other."""
    if request.param == "loopback":
        bus = LoopbackBus()

        async def loopback() -> Transport:
            t = LoopbackTransport(bus)
            await t.open()
            return t

        return loopback
    endpoint = request.getfixturevalue("router")

    async def real() -> Transport:
        t = ZenohTransport(zenoh_config(connect=[endpoint]))
        await t.open()
        return t

    return real


def run(coro: Coroutine[Any, Any, Any], timeout: float = 15.0) -> Any:
    return asyncio.run(asyncio.wait_for(coro, timeout))


async def eventually(predicate: Callable[[], object], timeout: float = 5.0) -> None:
    """Await until `predicate()` holds (poll with a deadline)."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    while not predicate():
        if loop.time() > deadline:
            raise AssertionError("condition not reached before the deadline")
        await asyncio.sleep(0.01)


@asynccontextmanager
async def opened(make: Factory, n: int) -> AsyncIterator[list[Transport]]:
    transports = [await make() for _ in range(n)]
    try:
        yield transports
    finally:
        for t in transports:
            await t.close()


async def ready(watcher: Transport, owner: Transport, name: str) -> None:
    """Wait until `watcher` sees a token that `owner` declares after its other declarations."""
    seen: set[str] = set()
    token = node_key("conf", KeyKind.NODE, name)
    watcher.watch(token, lambda key, alive: seen.add(key) if alive else seen.discard(key))
    owner.announce(token)
    await eventually(lambda: token in seen)


def test_publish_subscribe_in_order_on_the_loop_thread(make: Factory) -> None:
    async def body() -> None:
        async with opened(make, 2) as (pub, sub):
            got: list[bytes] = []
            threads: set[str] = set()

            def deliver(key: str, payload: bytes) -> None:
                threads.add(threading.current_thread().name)
                got.append(payload)

            sub.subscribe(KEY, deliver, QOS_DEFAULT)
            await ready(pub, sub, "sub1")
            sent = [i.to_bytes(4, "big") for i in range(500)]
            for payload in sent:
                pub.put(KEY, payload, QOS_DEFAULT)
            await eventually(lambda: len(got) == len(sent))
            assert got == sent
            assert threads == {threading.main_thread().name}

    run(body())


def test_query_reply_no_server_timeout_and_error(make: Factory) -> None:
    async def body() -> None:
        async with opened(make, 2) as (client, server):
            server.serve("twinfleet/conf/echo", lambda p, respond: respond(p + b"!", ""))
            slow: list[Any] = []  # a slow server: holds the request, answers after the timeout
            server.serve("twinfleet/conf/mute", lambda p, respond: slow.append(respond))
            server.serve("twinfleet/conf/err", lambda p, respond: respond(None, "server error: x"))
            await ready(client, server, "srv")
            results: dict[str, tuple[bytes | None, CallFailure | None, str]] = {}

            def done(name: str) -> Callable[[bytes | None, CallFailure | None, str], None]:
                return lambda reply, failure, reason: results.setdefault(name, (reply, failure,
                                                                                 reason))

            client.query("twinfleet/conf/echo", b"hi", 2000, done("echo"))
            client.query("twinfleet/conf/none", b"hi", 2000, done("none"))
            client.query("twinfleet/conf/mute", b"hi", 300, done("mute"))
            client.query("twinfleet/conf/err", b"hi", 2000, done("err"))
            await eventually(lambda: len(results) == 4)
            # what happened, as each transport saw it: Zenoh's own Timeout error reply, a
            # query finalised with no reply, the server's error reply
            assert results == {"echo": (b"hi!", None, ""),
                               "none": (None, CallFailure.NO_SERVER, "no server"),
                               "mute": (None, CallFailure.TIMEOUT, "timeout"),
                               "err": (None, CallFailure.SERVER_ERROR, "server error: x")}
            for respond in slow:
                respond(b"late", "")  # ignored by the caller; finalises the query

    run(body())


def test_liveliness_tokens_appear_and_disappear(make: Factory) -> None:
    async def body() -> None:
        async with opened(make, 1) as (watcher,):
            first = await make()
            first.announce(node_key("conf", KeyKind.NODE, "early"))
            events: list[tuple[str, bool]] = []
            watcher.watch(kind_expr("conf", KeyKind.NODE), lambda k, a: events.append((k, a)))
            early = node_key("conf", KeyKind.NODE, "early")
            await eventually(lambda: (early, True) in events)
            await first.close()
            await eventually(lambda: (early, False) in events)

    run(body())


def test_latched_topic_reaches_late_joiner(make: Factory) -> None:
    async def body() -> None:
        async with opened(make, 2) as (pub, late):
            pub.put("twinfleet/conf/map", b"v1", QOS_LATCHED)
            pub.put("twinfleet/conf/map", b"v2", QOS_LATCHED)
            got: list[bytes] = []
            late.subscribe("twinfleet/conf/map", lambda k, p: got.append(p), QOS_LATCHED)
            # The late joiner ends up with the latest value. It may also see v1 (the puts can
            # still be in flight when it subscribes) or v2 twice (history, then live).
            await eventually(lambda: bool(got) and got[-1] == b"v2")
            assert set(got) <= {b"v1", b"v2"}

    run(body())


@pytest.mark.parametrize(("pattern", "key", "expected"), [
    ("a/b", "a/b", True), ("a/*", "a/b", True), ("a/*", "a/b/c", False),
    ("a/**", "a/b/c", True), ("a/**", "a", True), ("a/**", "a/@x/c", False),
    ("a/*/c", "a/@x/c", False), ("a/@x/*", "a/@x/c", True),
])
def test_loopback_key_matching(pattern: str, key: str, expected: bool) -> None:
    assert key_matches(pattern, key) is expected
