"""Fast tests of the viewer's state, its web app (no Zenoh), trace documents and MCAP writing."""

from __future__ import annotations

import asyncio
import json
import re
from pathlib import Path

import msgpack
import pytest
from aiohttp import test_utils
from mcap.reader import make_reader
from viewer_support import api

from twinfleet.cli import main
from twinfleet.nodes.msgs import (
    Collision,
    FleetStatus,
    ObstacleScan,
    OccupancyGrid,
    RobotPose,
    RobotStatus,
)
from twinfleet.nodes.scene import RobotScene
from twinfleet.runtime.contract.messages import String, encode
from twinfleet.runtime.tools.record.recorder import McapRecorder, message_schema
from twinfleet.runtime.tools.view.viewer import make_app
from twinfleet.runtime.tools.view.viewstate import LiveState, trace_document

ROOT = Path(__file__).resolve().parents[2]
GRID = OccupancyGrid(3, 2, 0.25, (0.0, 0.0, 0.0), bytes([0, 100, 0, 0, 0, 100]))


def feed(state: LiveState, topic: str, msg: object, fleet: str = "f", seq: int = 1) -> None:
    state.on_sample(f"twinfleet/{fleet}{topic}", encode(msg, seq=seq, sender="map_server"))


def test_live_state_folds_messages_and_hands_out_changes_once():
    state = LiveState("*", RobotScene())
    feed(state, "/map", GRID)
    feed(state, "/poses", RobotPose("r2", (1, 1), 2, 1))
    feed(state, "/poses", RobotPose("r1", (0, 0), 2, 1))
    feed(state, "/r1/scan", ObstacleScan("r1", ((0, 2),)))
    feed(state, "/r1/status", RobotStatus("r1", "moving", (0, 0), (1, 2), 1, 0, 50))
    feed(state, "/poses", RobotPose("r9", (0, 1), 2, 1), fleet="other")  # locked on fleet f
    first = state.take_update()
    assert first["fleet"] == "f" and first["map"]["width"] == 3
    assert first["order"] == ["r1", "r2"]
    assert state.snapshot()["columns"] == ["mode", "cell", "goal", "waits", "failures", "arrived"]
    assert first["robots"]["r1"]["scan"] == [[2.5, 0.5]]  # cell (0, 2)'s centre, in cells
    assert first["robots"]["r1"]["row"] == {"mode": "moving", "cell": "(0,0)", "goal": "(1,2)",
                                            "waits": "1", "failures": "0", "arrived": "no"}
    assert first["robots"]["r1"]["goal"] == [2.5, 1.5]
    assert first["robots"]["r1"]["trail"] == {"start": 0, "items": [[0.5, 0.5]]}
    assert state.take_update() is None
    feed(state, "/map", GRID)  # the same sample again (a latched copy): not re-sent
    assert state.take_update() is None
    feed(state, "/poses", RobotPose("r1", (0, 1), 2, 1), seq=2)
    feed(state, "/fleet_status", FleetStatus(("r2", "r1"), ((1, 1), (0, 1)), 1, 60))
    feed(state, "/collisions", Collision("r1", "r2", (0, 1), (1, 1), 60))
    feed(state, "/twinfleet/shutdown", String("all robots arrived"))
    second = state.take_update()
    assert second["robots"] == {"r1": {"body": second["robots"]["r1"]["body"],
                                       "row": second["robots"]["r1"]["row"],
                                       "trail": {"start": 1, "items": [[1.5, 0.5]]}}}
    assert second["robots"]["r1"]["body"] == {"x": 1.5, "y": 0.5, "theta": 0.0, "half_m": 0.22}
    assert second["order"] == ["r2", "r1"]  # the map server's order wins
    assert second["collisions"] == {"start": 0, "items": [
        {"points": [[1.5, 0.5], [1.5, 1.5]], "label": "t=60 ms r1(0,1) × r2(1,1)",
         "caption": "r1 × r2 at t=60 ms"}]}
    assert second["ended"] == "all robots arrived"
    snap = state.snapshot()
    assert snap["robots"]["r1"]["trail"]["items"] == [[0.5, 0.5], [1.5, 0.5]]
    assert snap["stats"]["topics"]["/poses"] == 3 and "r9" not in snap["robots"]
    # every topic, whatever its type, with its latest message: the page's topic list
    assert snap["topics"]["/poses"]["type"] == "twinfleet_msgs/RobotPose"
    assert snap["topics"]["/poses"]["count"] == 3
    assert snap["topics"]["/poses"]["last"]["data"]["cell"] == [0, 1]
    assert second["topics"].keys() == {"/poses", "/fleet_status", "/collisions",
                                       "/twinfleet/shutdown"}


def test_live_state_restarts_a_robot_when_the_fleet_is_launched_again():
    state = LiveState("f", RobotScene())
    for stamp, cell in ((4000, (0, 0)), (4100, (0, 1)), (4200, (0, 2))):
        state.on_sample("twinfleet/f/poses", encode(RobotPose("r1", cell, 2, 1), stamp_ms=stamp))
    state.on_sample("twinfleet/f/twinfleet/shutdown", encode(String("all robots arrived")))
    assert state.take_update()["ended"] == "all robots arrived"
    state.on_sample("twinfleet/f/poses", encode(RobotPose("r1", (5, 5), 2, 1), stamp_ms=50))
    update = state.take_update()
    assert update["robots"]["r1"]["trail"] == {"start": 0, "items": [[5.5, 5.5]]}
    assert update["ended"] is None


def test_live_state_compares_stamps_per_sender_not_across_senders():
    """The map server publishes the robots' scans on its own clock, which lags theirs when it
    is busy: a scan stamped seconds behind r1's last pose is not a new run."""
    state = LiveState("f", RobotScene())
    pose = encode(RobotPose("r1", (0, 0), 2, 1), stamp_ms=4000, sender="r1")
    state.on_sample("twinfleet/f/poses", pose)
    state.on_sample("twinfleet/f/r1/status", encode(RobotStatus("r1", "moving", (0, 0), (3, 3),
                                                                0, 0, 4000), stamp_ms=4000, sender="r1"))
    state.on_sample("twinfleet/f/r1/scan", encode(ObstacleScan("r1", ((1, 1),)), stamp_ms=500,
                                                  sender="map_server"))
    update = state.take_update()
    assert "reset" not in update["robots"]["r1"]
    assert update["robots"]["r1"]["row"]["mode"] == "moving"
    assert state.snapshot()["robots"]["r1"]["trail"]["items"] == [[0.5, 0.5]]
    # the same sender going back is a new run: the page is told to drop the old status
    state.on_sample("twinfleet/f/poses", encode(RobotPose("r1", (5, 5), 2, 1), stamp_ms=50,
                                                sender="r1"))
    update = state.take_update()
    assert update["robots"]["r1"]["reset"] is True
    assert update["robots"]["r1"]["row"] == {"cell": "(5,5)", "arrived": "no"}  # no old mode
    assert state.snapshot()["robots"]["r1"]["trail"]["items"] == [[5.5, 5.5]]


def test_live_state_without_a_scene_lists_topics_and_draws_nothing():
    state = LiveState("f")
    feed(state, "/map", GRID)
    feed(state, "/poses", RobotPose("r1", (0, 0), 2, 1))
    snap = state.snapshot()
    assert snap["map"] is None and snap["robots"] == {} and snap["columns"] == []
    assert snap["topics"]["/poses"]["type"] == "twinfleet_msgs/RobotPose"


def test_live_state_draws_what_arrived_before_its_scene_was_known():
    state = LiveState("f", scene_known=False)
    feed(state, "/map", GRID)
    feed(state, "/poses", RobotPose("r1", (0, 0), 2, 1), seq=1)
    feed(state, "/poses", RobotPose("r1", (0, 1), 2, 1), seq=2)
    assert state.snapshot()["robots"] == {} and state.snapshot()["stats"]["messages"] == 3
    state.set_scene(RobotScene())
    update = state.take_update()
    assert update["map"]["width"] == 3 and update["columns"][0] == "mode"
    assert update["robots"]["r1"]["trail"] == {"start": 0, "items": [[0.5, 0.5], [1.5, 0.5]]}
    feed(state, "/poses", RobotPose("r1", (1, 1), 2, 1), seq=3)
    assert state.take_update()["robots"]["r1"]["body"]["y"] == 1.5


def test_live_state_ignores_garbage():
    state = LiveState("f")
    state.on_sample("twinfleet/f/poses", b"\xc1 not msgpack")
    state.on_sample("twinfleet/f/poses", msgpack.packb({"type": 3}))
    state.on_sample("elsewhere/f/poses", encode(RobotPose("r1", (0, 0), 2, 1)))
    assert state.snapshot()["robots"] == {} and state.messages == 2


def test_web_app_serves_page_state_and_websocket_updates():
    async def scenario() -> None:
        state = LiveState("f", RobotScene())
        feed(state, "/map", GRID)
        app = make_app(state=state, info={"fleet": "f"})
        async with test_utils.TestClient(test_utils.TestServer(app)) as client:
            page = await client.get("/")
            assert "twinfleet view" in await page.text()
            script = await client.get("/static/viewer.js")
            assert script.status == 200 and "twinfleetView" in await script.text()
            assert (await (await client.get("/api/info")).json())["mode"] == "live"
            assert (await client.get("/api/trace")).status == 404
            ws = await client.ws_connect("/ws")
            snap = await ws.receive_json(timeout=5)
            assert snap["kind"] == "snapshot" and snap["map"]["height"] == 2
            feed(state, "/poses", RobotPose("r1", (1, 2), 0, 1))
            update = await ws.receive_json(timeout=5)
            while "r1" not in update["robots"]:  # an earlier flush may carry the map
                update = await ws.receive_json(timeout=5)
            body = update["robots"]["r1"]["body"]
            assert update["kind"] == "update" and (body["x"], body["y"]) == (2.5, 1.5)
            await ws.close()

    asyncio.run(scenario())


def test_trace_document_has_map_robots_and_steps(tmp_path):
    from twinfleet.checker.driver import CheckOptions, check

    trace = tmp_path / "headon.trace.json"
    assert check(ROOT / "twinfleet" / "launch" / "headon.yaml", CheckOptions(trace_out=str(trace))).status == "violated"
    doc = trace_document(trace)
    raw = json.loads(trace.read_text())
    first = doc["frames"][0]
    assert first["order"] == ["r1", "r2"] and doc["columns"][0] == "mode"
    # start (5, 1) and goal (5, 10) of r1, as the centres of those cells
    assert first["robots"]["r1"]["start"] == [1.5, 5.5] and first["robots"]["r1"]["goal"] == [10.5, 5.5]
    assert first["robots"]["r1"]["row"]["mode"] == "planning"
    assert (doc["map"]["width"], doc["map"]["height"]) == (12, 12)
    assert len(doc["steps"]) == len(raw["steps"]) and doc["message"] == raw["message"]
    assert len(doc["frames"]) == len(raw["steps"]) + 1
    marks = doc["frames"][-1]["collisions"]  # headon ends in a collision: at both robots' cells
    assert len(marks) == 1 and re.fullmatch(r"\(\d+,\d+\) × \(\d+,\d+\)", marks[0]["label"])
    assert all("collisions" not in f for f in doc["frames"][1:-1])  # none before
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "other"}')
    with pytest.raises(ValueError, match="not a twinfleet-trace/1 trace"):
        trace_document(bad)


def test_schema_of_a_registered_type_and_of_an_unknown_one():
    pose = message_schema("twinfleet_msgs/RobotPose")
    data = pose["properties"]["data"]
    assert set(data["properties"]) == {"robot", "cell", "direction", "velocity", "done"}
    assert data["properties"]["cell"]["prefixItems"] == [{"type": "integer"}] * 2
    assert data["required"] == ["robot", "cell", "direction", "velocity"]
    grid = message_schema("twinfleet_msgs/OccupancyGrid")["properties"]["data"]["properties"]
    assert grid["data"]["contentMediaType"] == "application/octet-stream"
    other = message_schema("x_msgs/Unknown", {"a": 1, "b": [1.5], "c": {"d": "e"}})["properties"]["data"]
    assert other["properties"]["b"] == {"type": "array", "items": {"type": "number"}}
    assert "inferred" in other["description"]


def test_recorder_writes_channels_schemas_and_increasing_log_times(tmp_path):
    path = tmp_path / "x.mcap"
    rec = McapRecorder(path.open("wb"), latched=("/map",))
    payloads = [encode(RobotPose("r1", (0, i), 2, 1), seq=i + 1) for i in range(50)]
    for p in payloads:
        rec.write("twinfleet/f/poses", p)
    rec.write("twinfleet/f/map", encode(GRID))
    rec.write("twinfleet/f/junk", b"\xc1")
    rec.close()
    with path.open("rb") as f:
        rows = list(make_reader(f).iter_messages(log_time_order=True))
    assert [m.data for _, ch, m in rows if ch.topic == "/poses"] == payloads
    times = [m.log_time for _, _, m in rows]
    assert times == sorted(set(times))
    kinds = {ch.topic: (s.name, ch.metadata["durability"]) for s, ch, _ in rows}
    assert kinds == {"/poses": ("twinfleet_msgs/RobotPose", "volatile"),
                     "/map": ("twinfleet_msgs/OccupancyGrid", "transient_local"),
                     "/junk": ("twinfleet/Undecodable", "volatile")}
    assert rec.undecodable == 1 and rec.messages == 52


def test_cli_of_view_record_play(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("TWINFLEET_CONNECT", raising=False)
    assert main(["record", "-o", str(tmp_path / "x.mcap")]) == 2
    assert "needs a SCENARIO" in capsys.readouterr().err
    assert main(["record", "twinfleet/launch/c1a.yaml", "--connect", "tcp/127.0.0.1:1", "-o", "x.mcap"]) == 2
    assert "not both" in capsys.readouterr().err
    assert main(["play", str(tmp_path / "missing.mcap")]) == 2
    assert main(["view", "--trace", str(tmp_path / "missing.json"), "--port", "0"]) == 2
    for command, flags in (("view", ["--connect", "--fleet", "--port", "--trace"]),
                           ("record", ["--connect", "--duration", "--output", "--time-scale"]),
                           ("play", ["--rate", "--connect", "--listen", "--wait"])):
        with pytest.raises(SystemExit):
            main([command, "--help"])
        text = capsys.readouterr().out
        assert all(flag in text for flag in flags), (command, text)


def test_the_live_header_names_the_registry_without_a_frozen_waiting_word():
    """Found through the registry, the page says so; whether the fleet is reached is the
    link indicator's to say, so the header never reads "waiting" beside a running fleet."""
    import io

    import aiohttp

    from twinfleet.runtime.tools.view.viewer import serve

    async def scenario() -> dict:
        stop, loop = asyncio.Event(), asyncio.get_running_loop()
        ready: asyncio.Future[str] = loop.create_future()
        task = asyncio.create_task(serve(connect=None, fleet="*", port=0, out=io.StringIO(),
                                         ready=ready.set_result, stop=stop))
        try:
            url = await asyncio.wait_for(ready, 10)
            async with aiohttp.ClientSession() as http, http.get(api(url, "api/info")) as reply:
                return await reply.json()
        finally:
            stop.set()
            await asyncio.wait_for(task, 10)

    info = asyncio.run(scenario())
    assert info["connect"] == "the fleet registry", info
