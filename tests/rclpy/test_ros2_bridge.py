"""`launch --ros2` of an rclpy fleet: its standard-typed topics reach an independent ROS 2
peer (zenoh-ros2-sdk, not ours, in its own process) under their rosidl names and hashes,
with no mapping written. The rclpy turtle's controller commands /cmd_vel
(geometry_msgs/msg/Twist) on its timer; the peer subscribes with the hash it computes
itself from rosidl's definitions, so a decoded sample proves name, hash and CDR."""

from __future__ import annotations

import json
import queue
import sys
from pathlib import Path

import pytest
import zenoh

from tests.rclpy.oracle import running_fleet, wait_for_line
from tests.ros2.peer_events import read_events, start_peer, stop_peer, wait_event
from tests.support import pick_free_port
from twinfleet.runtime.host.zenoh_transport import zenoh_config

pytestmark = [pytest.mark.slow, pytest.mark.fleet, pytest.mark.timeout(120)]


def test_an_rclpy_fleet_shows_its_twist_to_a_ros2_peer():
    port = pick_free_port()
    router = zenoh.open(zenoh_config(listen=[f"tcp/127.0.0.1:{port}"], mode="router"))
    proc = None
    try:  # a far goal: the controller keeps commanding while the peer joins
        with running_fleet("turtle_system.yaml", 60.0, "--ros2", "--ros2-router",
                           f"tcp/127.0.0.1:{port}", "controller.goal:=100000") as fleet:
            wait_for_line(fleet, "[ros2]")
            proc = start_peer("sdk_twist_peer.py", port)
            events: queue.Queue = queue.Queue()
            read_events(proc, events)
            ready = wait_event(events, "ready")
            share = Path(sys.prefix) / "share" / "geometry_msgs" / "msg" / "Twist.json"
            rosidl = json.loads(share.read_text())["type_hashes"][0]["hash_string"]
            assert ready["twist_hash"] == rosidl
            heard = wait_event(events, "twist", timeout=30)
            assert heard["linear"] == [1.0, 0.0, 0.0] and heard["angular_z"] == 0.0
    finally:
        stop_peer(proc)
        router.close()
