"""The live bridge against an independent ROS 2 peer over real Zenoh: zenoh-ros2-sdk, in its
own process, through a router this test starts on 127.0.0.1 (multicast off).

The bridge's fleet side is fed fleet samples as `FleetTap` hands them over (key and msgpack
envelope); the ROS side is the real session. The peer lists the bridge's topics, receives
the map as a late joiner, poses and scans, and its /goal_pose reaches the bridge; malformed
samples on /goal_pose are dropped and counted."""

from __future__ import annotations

import queue
import time

import pytest
import zenoh

from tests.ros2.peer_events import read_events, start_peer, stop_peer, wait_event
from twinfleet.nodes.msgs import ObstacleScan, OccupancyGrid, RobotPose
from twinfleet.nodes.ros2_mapping import RobotRos2Mapping
from twinfleet.ros2.bridge import RosSide, ros_config
from twinfleet.runtime.contract.messages import encode
from twinfleet.runtime.fleet.live_fleet import free_port
from twinfleet.runtime.host.zenoh_transport import zenoh_config

pytestmark = [pytest.mark.slow, pytest.mark.timeout(90)]
GRID = OccupancyGrid(4, 3, 0.5, (0.0, 0.0, 0.0), bytes([0, 100, 255, 0] * 3))


def test_an_independent_ros2_peer_sees_the_fleet_and_reaches_it(tmp_path):
    port = free_port()
    router = zenoh.open(zenoh_config(listen=[f"tcp/127.0.0.1:{port}"], mode="router"))
    session = zenoh.open(ros_config(f"tcp/127.0.0.1:{port}"))
    goals: list = []
    side = RosSide(session, RobotRos2Mapping(),
                   inbound={"/goal_pose": "geometry_msgs/msg/PoseStamped"},
                   on_inbound=lambda *a: goals.append(a))
    proc = None
    try:
        side.deliver("twinfleet/f/map", encode(GRID, seq=1, stamp_ms=10))  # before the peer
        side.deliver("twinfleet/f/poses", encode(RobotPose("r1", (1, 1), 0, 1), stamp_ms=20))
        proc = start_peer("sdk_peer.py", port)
        events: queue.Queue = queue.Queue()
        read_events(proc, events)
        topics = dict((t, types) for t, types in wait_event(events, "topics")["topics"])
        assert topics["/map"] == ["nav_msgs/msg/OccupancyGrid"]
        assert topics["/r1/pose"] == ["geometry_msgs/msg/PoseStamped"]
        assert topics["/goal_pose"] == ["geometry_msgs/msg/PoseStamped"]
        grid = wait_event(events, "map")  # published before the peer existed: from the cache
        assert (grid["width"], grid["height"], grid["resolution"]) == (4, 3, 0.5)
        assert grid["data"][:4] == [0, 100, -1, 0]
        wait_event(events, "ready")
        time.sleep(0.5)  # the peer's subscriptions reach the router (no matching API in the SDK)
        side.deliver("twinfleet/f/poses", encode(RobotPose("r1", (1, 2), 2, 1), stamp_ms=30))
        pose = wait_event(events, "pose")
        assert pose["frame"] == "map" and (pose["x"], pose["y"]) == (1.25, 0.75)
        side.deliver("twinfleet/f/r1/scan", encode(ObstacleScan("r1", ((1, 3),)), stamp_ms=40))
        scan = wait_event(events, "scan")
        assert scan["frame"] == "r1/base_link" and scan["beams"] == 360
        assert scan["finite"] == [pytest.approx(0.5)]
        proc.stdin.write("goal\n")
        proc.stdin.flush()
        wait_event(events, "goal_sent")
        end = time.monotonic() + 10
        while not goals and time.monotonic() < end:
            time.sleep(0.02)
        assert goals and goals[0][2]["pose"]["position"] == {"x": 1.5, "y": 2.5, "z": 0.0}
        # malformed samples on the same key: no attachment, garbage, NaN
        key = side.graph.endpoints[next(k for k in side.graph.endpoints
                                        if k[2] == "/goal_pose")].key
        session.put(key, b"\x00\x01\x00\x00\x01")
        session.put(key, b"junk", attachment=bytes(16) + b"\x10" + bytes(16))
        session.put(key, b"\x00\x01\x00\x00", attachment=bytes(33))  # GID length 0
        nan = side.graph.types.encode("geometry_msgs/msg/PoseStamped",
                                      {"pose": {"position": {"x": float("nan")}}})
        session.put(key, nan, attachment=bytes(16) + b"\x10" + bytes(16))
        end = time.monotonic() + 10
        while sum(side.check.dropped.values()) < 4 and time.monotonic() < end:
            time.sleep(0.02)
        assert dict(side.check.dropped) == {"no attachment": 1, "malformed": 1, "not finite": 1,
                                            "bad attachment": 1}
        assert side.check.accepted == 1
    finally:
        stop_peer(proc)
        side.close()
        session.close()
        router.close()
