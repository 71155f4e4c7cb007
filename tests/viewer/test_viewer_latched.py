"""The latched /map reaches a viewer that joins a running fleet late.

C1a runs at time scale 1 (a minute of fleet time, stopped by the fixture).
Once the map server's first scan is seen, the map was published already; only
then does `twinfleet view` start. Its page state and its websocket snapshot
must hold the map (the bytes the map server publishes), exactly once, while a
plain subscriber that joined at the same moment gets nothing on /map.
"""

from __future__ import annotations

import asyncio
import base64
import time

import aiohttp
import pytest
import zenoh
from viewer_support import ROOT, api, free_port, get_json, poll, printed_url

from twinfleet.runtime.access.fleetauth import login_settings, registry_auth
from twinfleet.runtime.host.zenoh_transport import zenoh_config
from twinfleet.runtime.scenario.scenes import load_scene
from twinfleet.runtime.scenario.spec import load_scenario
from twinfleet.runtime.tools.view.viewstate import start_map

pytestmark = [pytest.mark.slow, pytest.mark.timeout(60)]


def _open_when_up(endpoint: str) -> zenoh.Session:
    deadline = time.monotonic() + 15
    while True:
        try:
            # the fleet's read-only login, from its registry entry (README "Trust model")
            settings = login_settings(registry_auth(endpoint))
            return zenoh.open(zenoh_config(connect=[endpoint], mode="client", settings=settings))
        except zenoh.ZError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.1)


async def _websocket_snapshot(url: str) -> dict:
    async with aiohttp.ClientSession() as http, http.ws_connect(api(url, "ws")) as ws:
        return await asyncio.wait_for(ws.receive_json(), timeout=5)


def test_late_viewer_receives_the_latched_map(cli):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    cli("launch", str(ROOT / "twinfleet" / "launch" / "c1a.yaml"), "--time-scale", "1", "--listen", endpoint,
        log="fleet.log")
    session = _open_when_up(endpoint)
    scans, late_maps = [], []
    subs = [session.declare_subscriber("twinfleet/c1a/r1/scan", scans.append)]
    try:
        poll(lambda: scans, 20, "the map server's first scan (so /map is already published)")
        subs.append(session.declare_subscriber("twinfleet/c1a/map", late_maps.append))
        port = free_port()
        joined = time.monotonic()
        viewer = cli("view", "--connect", endpoint, "--fleet", "c1a", "--port", str(port),
                     log="viewer.log")
        url = printed_url(viewer.log)
        state = poll(lambda: (s := get_json(api(url, "api/state"))) and s["map"] and s, 15,
                     "the late viewer to receive /map")
        print(f"late viewer had the map {time.monotonic() - joined:.2f} s after it started")
        scenario = load_scenario(ROOT / "twinfleet" / "launch" / "c1a.yaml")
        expected = start_map(scenario, load_scene(scenario.scene))
        assert (state["map"]["width"], state["map"]["height"]) == (50, 50)
        assert base64.b64decode(state["map"]["cells"]) == base64.b64decode(expected["cells"])
        assert state["stats"]["topics"]["/map"] == 1  # history and live copies counted once
        snapshot = asyncio.run(_websocket_snapshot(url))
        assert snapshot["kind"] == "snapshot" and snapshot["map"] == state["map"]
        assert late_maps == [], "a plain late subscriber got /map: the test did not join late"
    finally:
        for sub in subs:
            sub.undeclare()
        session.close()
