"""The Zenoh → loop hand-off: bounded for samples, never blocking Zenoh's threads."""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Coroutine
from typing import Any

import pytest

from twinfleet.runtime.contract.node import QOS_DEFAULT
from twinfleet.runtime.host.zenoh_transport import Handoff

zenoh = pytest.importorskip("zenoh")

from twinfleet.runtime.fleet.launcher import free_port  # noqa: E402
from twinfleet.runtime.host.zenoh_transport import ZenohTransport, zenoh_config  # noqa: E402


def run(coro: Coroutine[Any, Any, Any], timeout: float = 15.0) -> Any:
    return asyncio.run(asyncio.wait_for(coro, timeout))


def test_offer_drops_and_counts_beyond_capacity_push_does_not() -> None:
    async def body() -> tuple[list[int], int, int]:
        handoff = Handoff(asyncio.get_running_loop(), capacity=4)
        got: list[int] = []
        accepted = [handoff.offer(got.append, i) for i in range(10)]
        handoff.push(got.append, 100)  # control traffic is never dropped
        assert accepted == [True] * 4 + [False] * 6
        await asyncio.sleep(0)
        return got, handoff.overflow, handoff.wakeups

    got, overflow, wakeups = run(body())
    assert got == [0, 1, 2, 3, 100]
    assert overflow == 6
    assert wakeups == 1  # one wake-up for the whole burst


def test_after_drain_runs_once_per_burst_after_the_burst() -> None:
    async def body() -> list[str]:
        handoff = Handoff(asyncio.get_running_loop())
        events: list[str] = []
        handoff.after_drain.append(lambda: events.append("end"))
        for name in ("a", "b"):
            handoff.push(events.append, name)
        await asyncio.sleep(0)
        handoff.push(events.append, "c")
        await asyncio.sleep(0)
        return events

    assert run(body()) == ["a", "b", "end", "c", "end"]


def test_pushes_from_other_threads_arrive_in_order_on_the_loop() -> None:
    async def body() -> tuple[list[int], set[str]]:
        loop = asyncio.get_running_loop()
        handoff = Handoff(loop)
        got: list[int] = []
        threads: set[str] = set()

        def on_loop(i: int) -> None:
            threads.add(threading.current_thread().name)
            got.append(i)

        def produce() -> None:
            for i in range(5000):
                handoff.push(on_loop, i)

        await asyncio.to_thread(produce)
        while len(got) < 5000:
            await asyncio.sleep(0.01)
        return got, threads

    got, threads = run(body())
    assert got == list(range(5000))
    assert threads == {threading.main_thread().name}


@pytest.fixture
def router() -> Any:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    session = zenoh.open(zenoh_config(listen=[endpoint], mode="router"))
    try:
        yield endpoint
    finally:
        session.close()


@pytest.mark.fleet
def test_a_stalled_loop_drops_and_counts_samples_without_blocking_zenoh(router: str) -> None:
    """The loop sleeps while 300 samples arrive: 50 wait, 250 are counted as overflow."""

    async def body() -> tuple[int, dict[str, int], float]:
        sub = ZenohTransport(zenoh_config(connect=[router]), max_pending=50)
        pub = ZenohTransport(zenoh_config(connect=[router]))
        await sub.open()
        await pub.open()
        try:
            got: list[bytes] = []
            key = "twinfleet/handoff/topic"
            sub.subscribe(key, lambda k, p: got.append(p), QOS_DEFAULT)
            probe = pub.session.declare_publisher(key)  # type: ignore[union-attr]
            deadline = time.monotonic() + 5
            while not probe.matching_status.matching and time.monotonic() < deadline:
                await asyncio.sleep(0.01)  # the subscription is known: no sample is lost to a race
            probe.undeclare()
            started = time.monotonic()
            for i in range(300):  # the loop is busy here: nothing is drained meanwhile
                pub.put(key, i.to_bytes(4, "big"), QOS_DEFAULT)  # BLOCK: nothing lost on the way
            wait_until = time.monotonic() + 5
            while sub.statistics().overflow < 250 and time.monotonic() < wait_until:
                time.sleep(0.01)  # blocks the loop on purpose
            put_s = time.monotonic() - started
            await asyncio.sleep(0.2)
            return len(got), sub.statistics(), put_s
        finally:
            await pub.close()
            await sub.close()

    received, stats, put_s = run(body())
    assert received == 50
    assert stats.overflow == 250
    assert put_s < 5  # the publisher never stalled behind a blocked subscriber thread
