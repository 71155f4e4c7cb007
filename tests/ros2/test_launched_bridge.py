"""`twinfleet launch` with a `ros2:` section against an independent ROS 2 peer: zenoh-ros2-sdk
(not ours) in its own process, through a plain Zenoh router on 127.0.0.1 that stands where
rmw_zenohd would (multicast off).

The launched fleet (headon: a map server and two robots, each its own process) appears as ROS
nodes of their own names; the peer receives the map as a late joiner, a pose and a scan with
values that fit the map; its /goal_pose reaches robot r1 (r1 reports the new goal on its
status topic, counts one external input, and the verdict says the run took it); malformed
samples and a goal outside the map are dropped and counted by the bridge."""

from __future__ import annotations

import contextlib
import json
import math
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import zenoh

from tests.support import child_env, pick_free_port
from twinfleet.nodes.ros2_mapping import GridFrame
from twinfleet.ros2.cdr import RosTypes
from twinfleet.ros2.wire import data_key
from twinfleet.runtime.access.fleetauth import monitor_auth
from twinfleet.runtime.access.registry import find_fleet
from twinfleet.runtime.contract.messages import decode
from twinfleet.runtime.host.keys import topic_key
from twinfleet.runtime.host.zenoh_transport import zenoh_config
from twinfleet.runtime.scenario.files import copy_example
from twinfleet.runtime.tools.monitor.tap import tap_config

pytestmark = [pytest.mark.slow, pytest.mark.timeout(90)]
POSE = "geometry_msgs/msg/PoseStamped"


def _lines(stream, out: queue.Queue) -> None:
    for line in stream:
        out.put(line)


def _wait(lines: queue.Queue, seen: list[str], test, what: str, timeout: float = 20.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            line = lines.get(timeout=max(0.01, end - time.monotonic()))
        except queue.Empty:
            break
        seen.append(line)
        found = test(line)
        if found:
            return found
    raise AssertionError(f"no {what}; saw:\n{''.join(seen[-30:])}")


class PeerEvents:
    """The peer's JSON events, kept by kind (they come in any order)."""

    def __init__(self, lines: queue.Queue) -> None:
        self.lines, self.seen, self.by_kind = lines, [], {}

    def get(self, kind: str, timeout: float = 20.0) -> dict:
        def test(line: str):
            if line.startswith("{"):
                event = json.loads(line)
                self.by_kind.setdefault(event["event"], []).append(event)
            return bool(self.by_kind.get(kind))
        if not self.by_kind.get(kind):
            _wait(self.lines, self.seen, test, kind, timeout)
        return self.by_kind[kind].pop(0)


def _scenario(tmp_path: Path, port: int) -> Path:
    path = copy_example("headon", tmp_path)[0][0]
    path.write_text(path.read_text() + f"ros2: {{router: tcp/127.0.0.1:{port}, "
                                       "inbound: {/goal_pose: /r1/goal}}\n")
    return path


def _watch_status(endpoint: str, extra: dict, goals: list) -> zenoh.Session:
    session = zenoh.open(tap_config(endpoint, monitor_auth(extra)))
    session.declare_subscriber(topic_key("headon", "/r1/status"),
                               lambda s: goals.append(tuple(decode(s.payload.to_bytes()).msg.goal)))
    return session


def test_a_launched_fleet_is_a_citizen_of_a_ros2_network(tmp_path):
    port = pick_free_port()
    router = zenoh.open(zenoh_config(listen=[f"tcp/127.0.0.1:{port}"], mode="router"))
    env = child_env()
    launcher = subprocess.Popen([sys.executable, "-m", "twinfleet", "launch",
                                 str(_scenario(tmp_path, port)), "--timeout", "60", "-v"],
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                env=env)
    fleet_out: queue.Queue = queue.Queue()
    threading.Thread(target=_lines, args=(launcher.stdout, fleet_out), daemon=True).start()
    seen: list[str] = []
    peer = status = mine = None
    try:
        _wait(fleet_out, seen, lambda line: "[ros2] fleet 'headon'" in line, "bridge up", 30)
        time.sleep(1.0)  # the map is published at start: the peer joins well after it
        peer = subprocess.Popen([sys.executable, str(Path(__file__).with_name(
            "sdk_fleet_peer.py")), str(port)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
            text=True, env=dict(env, ZENOH_CONFIG_OVERRIDE="scouting/multicast/enabled=false"))
        lines: queue.Queue = queue.Queue()
        threading.Thread(target=_lines, args=(peer.stdout, lines), daemon=True).start()
        events = PeerEvents(lines)
        nodes = events.get("nodes")["nodes"]
        assert {"map_server", "r1", "r2", "twinfleet_bridge"} <= set(nodes)
        topics = dict(events.get("topics")["topics"])
        assert topics["/map"] == ["nav_msgs/msg/OccupancyGrid"]
        assert topics["/r1/scan"] == ["sensor_msgs/msg/LaserScan"]
        assert topics["/tf"] == ["tf2_msgs/msg/TFMessage"]
        assert topics["/fleet_status"] == ["twinfleet_msgs/msg/FleetStatus"]  # by its fields
        info = {e["topic"]: e for e in (events.get("info") for _ in range(3))}
        assert info["/map"]["publishers"] == ["map_server"]
        assert info["/r1/pose"]["publishers"] == ["r1"]
        assert info["/goal_pose"]["subscribers"] == ["r1"]
        grid = events.get("map")
        assert (grid["width"], grid["height"], grid["frame"]) == (12, 12, "map")
        assert grid["resolution"] == pytest.approx(0.255) and 0 < grid["occupied"] < 144
        frame = GridFrame(grid["resolution"], (*grid["origin"], 0.0), (12, 12))
        pose = events.get("pose")
        frame.cell_of(pose["x"], pose["y"])  # raises for a point outside the map
        assert pose["frame"] == "map" and pose["z"] == 0.0
        assert pose["qz"] ** 2 + pose["qw"] ** 2 == pytest.approx(1.0)
        scan = events.get("scan")
        assert scan["frame"] == "r1/base_link" and scan["beams"] == 360 and scan["finite"] > 0
        assert scan["range_max"] == pytest.approx(math.hypot(12, 12) * 0.255)
        events.get("ready")
        goals: list = []
        status = _watch_status(find_fleet("headon").endpoint, find_fleet("headon").extra, goals)
        x, y = frame.centre((6, 3))  # a free cell of the corridor, not r1's goal (5, 10)
        peer.stdin.write(f"goal {x} {y}\n")
        peer.stdin.flush()
        _wait(fleet_out, seen, lambda line: "/goal_pose -> /r1/goal: forwarded (#1)" in line,
              "the goal forwarded")
        end = time.monotonic() + 10
        while (6, 3) not in goals and time.monotonic() < end:
            time.sleep(0.05)
        assert (6, 3) in goals, f"r1 never reported goal (6, 3): {goals}"
        # malformed and unmappable samples on the goal key, from a session of our own
        mine = zenoh.open(zenoh_config(connect=[f"tcp/127.0.0.1:{port}"]))
        types = RosTypes()
        key = data_key(0, "/goal_pose", POSE, types.type_hash(POSE))
        gid = bytes(16) + b"\x10" + bytes(16)
        mine.put(key, b"\x00\x01\x00\x00\x01")  # no attachment
        mine.put(key, b"junk", attachment=gid)
        mine.put(key, types.encode(POSE, {"pose": {"position": {"x": float("nan")}}}),
                 attachment=gid)
        mine.put(key, types.encode(POSE, {"header": {"frame_id": "map"},
                                          "pose": {"position": {"x": 99.0, "y": 99.0}}}),
                 attachment=gid)
        _wait(fleet_out, seen, lambda line: "dropped an inbound sample: outside the map" in line,
              "the goal outside the map dropped")
        # the forwarded goal, heard back from the fleet, is not published to ROS 2 again
        names = {str(r.ok.key_expr).split("/")[8]
                 for r in mine.liveliness().get("@ros2_lv/0/**", timeout=1.0) if r.ok is not None}
        assert "ros2_bridge" not in names and "r1" in names
    finally:
        if launcher.poll() is None:
            launcher.send_signal(signal.SIGINT)
        for proc in (peer,):
            if proc is not None:
                with contextlib.suppress(Exception):
                    proc.stdin.write("quit\n")
                    proc.stdin.flush()
                    proc.wait(timeout=10)
                if proc.poll() is None:
                    proc.kill()
        try:
            launcher.wait(timeout=30)
        except subprocess.TimeoutExpired:
            launcher.kill()
        for session in (status, mine, router):
            if session is not None:
                session.close()
    while not fleet_out.empty():
        seen.append(fleet_out.get())
    out = "".join(seen)
    summary = next(line for line in seen if "[ros2] published" in line)
    assert "forwarded 1, dropped 4" in summary, summary
    for reason in ("no attachment 1", "malformed 1", "not finite 1", "outside the map 1"):
        assert reason in summary, summary
    assert ("took external input (from outside the fleet; the checked model has no such "
            "input): r1: 1 on /r1/goal from the ROS 2 bridge") in out, out[-3000:]
    r1_stopped = next(line for line in seen if line.startswith("[r1] stopped:"))
    assert "external_input=1 " in r1_stopped and "rejected_forged=0" in r1_stopped
