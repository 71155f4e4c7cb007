"""`twinfleet foxglove` serves a live C1a over the Foxglove WebSocket
protocol, and a protocol client decodes the map grid, robot entities and a scan.

The client speaks the Foxglove WebSocket protocol itself (aiohttp's WebSocket
client, no foxglove code). foxglove-sdk 0.30 negotiates it under the subprotocol
name ``foxglove.sdk.v1`` (the one the Foxglove app offers today) and refuses the
older ``foxglove.websocket.v1`` name (checked: HTTP 400); the messages are those
of the ws-protocol spec. The client reads the server's ``advertise`` messages, subscribes to
the channels, and decodes each binary ``MessageData`` frame (opcode 1,
subscription id, log time, payload) with the schema the channel advertised
(a protobuf FileDescriptorSet, or a JSON Schema for the raw topics). The
bridge starts first and waits for the fleet's router; C1a is then launched at
time scale 10.
"""

from __future__ import annotations

import asyncio
import base64
import json
import re
import struct
import time

import aiohttp
import pytest
from foxglove_support import decode_protobuf
from viewer_support import ROOT, free_port, poll, printed_url

pytestmark = [pytest.mark.slow, pytest.mark.timeout(90)]

ROBOTS = ["r1", "r2", "r3", "r4", "r5"]
SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]


async def _collect(url: str, launch, deadline_s: float) -> dict:
    """Subscribe to every advertised channel; decode until the map, five robots and a scan."""
    seen = {"grid": None, "robots": set(), "scan": None, "poses": None, "schemas": {}}
    channels: dict[int, dict] = {}
    subscriptions: dict[int, dict] = {}
    async with aiohttp.ClientSession() as http, http.ws_connect(url, protocols=SUBPROTOCOLS) as ws:
        assert ws.protocol in SUBPROTOCOLS
        launch()
        end = time.monotonic() + deadline_s
        while time.monotonic() < end and not _complete(seen):
            try:
                msg = await ws.receive(timeout=max(0.1, end - time.monotonic()))
            except TimeoutError:
                break
            if msg.type == aiohttp.WSMsgType.TEXT:
                await _on_text(ws, json.loads(msg.data), channels, subscriptions, seen)
            elif msg.type == aiohttp.WSMsgType.BINARY:
                _on_binary(msg.data, subscriptions, seen)
            else:
                break
    return seen


def _complete(seen: dict) -> bool:
    return bool(seen["grid"] and seen["robots"] >= set(ROBOTS) and seen["scan"] and seen["poses"])


async def _on_text(ws, doc: dict, channels: dict, subscriptions: dict, seen: dict) -> None:
    if doc.get("op") != "advertise":
        return
    wanted = []
    for channel in doc["channels"]:
        channels[channel["id"]] = channel
        seen["schemas"][channel["topic"]] = channel["schemaName"]
        sub_id = len(subscriptions) + 1
        subscriptions[sub_id] = channel
        wanted.append({"id": sub_id, "channelId": channel["id"]})
    await ws.send_str(json.dumps({"op": "subscribe", "subscriptions": wanted}))


def _on_binary(data: bytes, subscriptions: dict, seen: dict) -> None:
    assert data[0] == 0x01, f"unexpected binary opcode {data[0]}"
    sub_id, _log_time = struct.unpack_from("<IQ", data, 1)
    channel, payload = subscriptions[sub_id], data[13:]
    topic = channel["topic"]
    if channel["encoding"] == "protobuf":
        schema = base64.b64decode(channel["schema"])
        msg = decode_protobuf(channel["schemaName"], schema, payload)
        if topic == "/foxglove/map":
            seen["grid"] = msg
        elif topic == "/foxglove/robots":
            seen["robots"] |= {e.id.split("/")[1] for e in msg.entities if e.cubes and e.arrows}
        elif re.fullmatch(r"/foxglove/r\d+/scan", topic) and len(msg.data) >= 12:
            seen["scan"] = msg
    elif topic == "/poses":
        assert channel["encoding"] == "json" and channel["schemaEncoding"] == "jsonschema"
        schema = json.loads(channel["schema"])
        doc = json.loads(payload)
        assert set(doc["data"]) <= set(schema["properties"]["data"]["properties"])
        seen["poses"] = doc


def test_foxglove_protocol_client_gets_map_robots_and_scan_from_live_c1a(cli):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    port = free_port()
    bridge = cli("foxglove", "--connect", endpoint, "--fleet", "c1a", "--port", str(port),
                 log="foxglove.log")
    poll(lambda: "open connection ws://" in bridge.log.read_text(), 20, "the Foxglove server")

    def launch() -> None:
        cli("launch", str(ROOT / "twinfleet" / "launch" / "c1a.yaml"), "--time-scale", "10", "--listen",
            endpoint, log="fleet.log")

    seen = asyncio.run(_collect(printed_url(bridge.log), launch, 60))
    assert seen["grid"] is not None, bridge.log.read_text()
    grid = seen["grid"]
    assert grid.frame_id == "map" and grid.column_count == 50 and len(grid.data) == 2500
    assert abs(grid.cell_size.x - 0.255) < 1e-9 and grid.fields[0].name == "occupancy"
    assert sum(1 for b in grid.data if b == 100) > 0
    assert seen["robots"] >= set(ROBOTS), seen["robots"]
    assert len(seen["scan"].data) % seen["scan"].point_stride == 0
    assert seen["poses"]["type"] == "twinfleet_msgs/RobotPose"
    schemas = seen["schemas"]
    assert schemas["/foxglove/map"] == "foxglove.Grid"
    assert schemas["/foxglove/robots"] == "foxglove.SceneUpdate"
    assert schemas["/foxglove/r1/scan"] == "foxglove.PointCloud"
    assert schemas["/poses"] == "twinfleet_msgs/RobotPose"


def test_a_late_foxglove_client_still_gets_the_map(cli):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    fleet = cli("launch", str(ROOT / "twinfleet" / "launch" / "c1a.yaml"), "--time-scale", "1", "--listen",
                endpoint, log="fleet.log")
    poll(lambda: fleet.log.read_text().count("started") >= 6, 30, "the fleet's nodes")
    port = free_port()
    bridge = cli("foxglove", "--connect", endpoint, "--fleet", "c1a", "--port", str(port),
                 log="foxglove.log")
    poll(lambda: "open connection ws://" in bridge.log.read_text(), 20, "the Foxglove server")
    seen = asyncio.run(_collect(printed_url(bridge.log), lambda: None, 20))
    assert seen["grid"] is not None and seen["grid"].column_count == 50
