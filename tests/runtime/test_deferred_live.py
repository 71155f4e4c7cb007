"""Deferred service replies over Zenoh (native nodes, tests/checker/deferred_nodes.py):
each caller gets its own answer from a relay that replies from a later handler, a reply
sent after the caller's timeout leaves the caller's CallError as it was while the server
goes on (its query was finalised, no error), and a transport that closes answers the
queries it still holds."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from tests.checker.deferred_nodes import Answer, Asker, Backend, Relay, SlowRelay
from tests.support import child_env
from twinfleet import CallFailure, testing
from twinfleet.runtime.fleet.launcher import free_port
from twinfleet.runtime.host.zenoh_transport import ZenohTransport, zenoh_config

pytestmark = [pytest.mark.slow, pytest.mark.fleet, pytest.mark.timeout(120)]


@pytest.fixture(autouse=True)
def _env(monkeypatch: pytest.MonkeyPatch) -> None:
    for key, value in child_env().items():
        monkeypatch.setenv(key, value)


def test_each_caller_gets_its_own_deferred_reply_live():
    system = testing.system({"backend": Backend, "relay": Relay, "a0": Asker, "a1": Asker})

    async def both(fleet: testing.LiveFleet) -> None:
        for name in ("a0", "a1"):
            got = await fleet.message("/answered", lambda m, name=name: m.to == name,
                                      timeout_s=20)
            assert got == Answer(name, name)

    result = testing.run_live(system, both, timeout_s=60)
    assert result.ok and set(result.exit_codes.values()) == {0}, result


def test_a_reply_after_the_callers_timeout_is_the_callers_call_error():
    system = testing.system({"relay": SlowRelay, "a0": Asker})

    async def late(fleet: testing.LiveFleet) -> None:
        got = await fleet.message("/answered", timeout_s=20)
        assert got == Answer("a0", "error")  # the 1 s timeout came first
        assert await fleet.message("/late", timeout_s=20) == Answer("", "replied")
        with pytest.raises(TimeoutError):  # the late reply reached no handler
            await fleet.message("/answered", lambda m: m.to != "a0" or m.text != "error",
                                timeout_s=1.0)

    result = testing.run_live(system, late, timeout_s=60)
    assert result.ok and set(result.exit_codes.values()) == {0}, result


def test_a_query_held_when_the_server_closes_is_answered_with_a_server_error():
    zenoh = pytest.importorskip("zenoh")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = zenoh.open(zenoh_config(listen=[endpoint], mode="router"))

    async def body() -> list[tuple[Any, ...]]:
        server = ZenohTransport(zenoh_config(connect=[endpoint]))
        client = ZenohTransport(zenoh_config(connect=[endpoint]))
        await server.open()
        await client.open()
        try:
            held = asyncio.Event()
            server.serve("twinfleet/defer/srv", lambda payload, respond: held.set())
            results: list[tuple[Any, ...]] = []
            while not held.is_set():  # until a query reaches the server (discovery)
                client.query("twinfleet/defer/srv", b"hi", 10_000, lambda *a: results.append(a))
                await asyncio.sleep(0.05)
            await asyncio.sleep(0.2)
            assert all(r[1] is not CallFailure.SERVER_ERROR for r in results)  # none answered
            await server.close()
            for _ in range(200):
                if any(r[1] is CallFailure.SERVER_ERROR for r in results):
                    break
                await asyncio.sleep(0.05)
            return results
        finally:
            await server.close()
            await client.close()

    try:
        results = asyncio.run(body())
    finally:
        router.close()
    answered = [r for r in results if r[1] is CallFailure.SERVER_ERROR]
    assert answered and answered[0][0] is None, results
    assert "the server stopped before it replied" in answered[0][2]
