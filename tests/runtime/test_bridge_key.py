"""The bridge key over real Zenoh (127.0.0.1): a sample signed with it is taken on the node's
external keys only, and counted; elsewhere, and unsigned or with a key of no one, it is
refused as forged. The fleet key still opens every key."""

from __future__ import annotations

import asyncio

import pytest
import zenoh

from twinfleet.runtime.contract.node import QOS_DEFAULT
from twinfleet.runtime.core.guard import new_key, sign
from twinfleet.runtime.core.statistics import Rejection
from twinfleet.runtime.fleet.launcher import free_port
from twinfleet.runtime.host.zenoh_transport import ZenohTransport, zenoh_config

pytestmark = [pytest.mark.slow, pytest.mark.fleet, pytest.mark.timeout(30)]
GOAL, STATUS = "twinfleet/f/r1/goal", "twinfleet/f/r1/status"


def test_the_bridge_key_opens_the_external_topics_only() -> None:
    fleet_key, bridge_key, stranger = new_key(), new_key(), new_key()
    endpoint = f"tcp/127.0.0.1:{free_port()}"

    async def body() -> None:
        router = zenoh.open(zenoh_config(listen=[endpoint], mode="router"))
        node = ZenohTransport(zenoh_config(connect=[endpoint]), key=fleet_key,
                              bridge_key=bridge_key, external=frozenset({GOAL}))
        await node.open()
        sender = zenoh.open(zenoh_config(connect=[endpoint]))
        got: list[tuple[str, bytes]] = []
        try:
            for key in (GOAL, STATUS):
                node.subscribe(key, lambda k, p: got.append((k, p)), QOS_DEFAULT)
            await asyncio.sleep(0.3)  # the subscriptions reach the router
            sends = [(GOAL, b"bridge", bridge_key), (STATUS, b"bridge elsewhere", bridge_key),
                     (GOAL, b"stranger", stranger), (GOAL, b"fleet", fleet_key),
                     (STATUS, b"fleet", fleet_key)]
            for key, payload, signer in sends:
                sender.put(key, payload, attachment=sign(signer, key, payload))
            sender.put(GOAL, b"unsigned")
            deadline = asyncio.get_running_loop().time() + 10
            while (len(got) < 3 or node.statistics().refused[Rejection.FORGED] < 3) and \
                    asyncio.get_running_loop().time() < deadline:
                await asyncio.sleep(0.02)
        finally:
            await node.close()
            sender.close()
            router.close()
        assert sorted(got) == [(GOAL, b"bridge"), (GOAL, b"fleet"), (STATUS, b"fleet")]
        stats = node.statistics()
        assert stats.external == 1 and stats.refused[Rejection.FORGED] == 3

    asyncio.run(body())
