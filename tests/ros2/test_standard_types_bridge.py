"""Standard ROS 2 types cross the bridge under their real names and RIHS01, with no mapping.

A fleet message of a generated type (`twinfleet.interfaces`: geometry_msgs/Twist) or of
the contract's own std_msgs/String reaches an independent ROS 2 peer — zenoh-ros2-sdk
(not ours) in its own process, through a router on 127.0.0.1 (multicast off) — whose
subscription key carries the hash it computes itself from rosidl's definitions: the
sample arriving, decoded, is the proof that name, hash and CDR agree. The mapping the
bridge is given maps nothing.
"""

from __future__ import annotations

import contextlib
import json
import os
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import msgpack
import pytest
import yaml
import zenoh

from tests.ros2.peer_events import read_events, start_peer, stop_peer, wait_event
from tests.support import child_env
from twinfleet.interfaces import contract_type, freeze, load_interface
from twinfleet.ros2.bridge import RosSide, ros_config
from twinfleet.ros2.live import fleet_interfaces
from twinfleet.runtime.contract.messages import String, encode, message
from twinfleet.runtime.fleet.live_fleet import free_port
from twinfleet.runtime.host.zenoh_transport import zenoh_config

pytestmark = [pytest.mark.slow, pytest.mark.timeout(90)]
SHARE = Path(sys.prefix) / "share"
NODES = "tests.interfaces.twist_nodes"
Time = contract_type("builtin_interfaces/msg/Time")


class MapsNothing:
    """A mapping that maps no type: what the bridge carries here, it carries by itself."""

    latched: frozenset[str] = frozenset()
    mapped_types: frozenset[str] = frozenset()

    def outbound(self, topic, type_name, data, stamp_ms):
        return ()


def _rosidl_hash(package: str, name: str) -> str:
    doc = json.loads((SHARE / package / "msg" / f"{name}.json").read_text())
    return doc["type_hashes"][0]["hash_string"]


def _until(events: queue.Queue, kind: str, side: RosSide, send) -> dict:
    """Send until the peer hears it: its subscription reaches the router at a time no API of
    the SDK tells."""
    end = time.monotonic() + 20
    while time.monotonic() < end:
        send()
        with contextlib.suppress(AssertionError):
            return wait_event(events, kind, timeout=0.3)
    raise AssertionError(f"the peer never heard a {kind}")


def test_a_twist_and_a_string_reach_a_ros2_peer_by_their_rosidl_hashes():
    geometry = load_interface("geometry_msgs", "msg")
    twist = freeze(geometry.Twist(linear=geometry.Vector3(x=1.0), angular=geometry.Vector3(z=0.5)))
    port = free_port()
    router = zenoh.open(zenoh_config(listen=[f"tcp/127.0.0.1:{port}"], mode="router"))
    session = zenoh.open(ros_config(f"tcp/127.0.0.1:{port}"))
    side = RosSide(session, MapsNothing())
    side.interfaces = fleet_interfaces(side.graph.types)
    proc = None
    try:
        proc = start_peer("sdk_twist_peer.py", port)
        events: queue.Queue = queue.Queue()
        read_events(proc, events)
        ready = wait_event(events, "ready")
        assert ready["twist_hash"] == _rosidl_hash("geometry_msgs", "Twist")
        assert ready["string_hash"] == _rosidl_hash("std_msgs", "String")
        heard = _until(events, "twist", side, lambda: side.deliver(
            "twinfleet/f/cmd_vel", encode(twist, stamp_ms=10, sender="driver")))
        assert heard["linear"] == [1.0, 0.0, 0.0] and heard["angular_z"] == 0.5
        text = _until(events, "string", side, lambda: side.deliver(
            "twinfleet/f/status", encode(String("ok"), stamp_ms=20, sender="driver")))
        assert text["data"] == "ok"
        keys = {d.endpoint.topic: d.key for d in side.graph.endpoints.values()}
        assert keys["/cmd_vel"].endswith(
            "/geometry_msgs::msg::dds_::Twist_/" + _rosidl_hash("geometry_msgs", "Twist"))
        proc.stdin.write("topics\n")
        proc.stdin.flush()
        topics = dict(wait_event(events, "topics")["topics"])
        assert topics["/cmd_vel"] == ["geometry_msgs/msg/Twist"]
        assert topics["/status"] == ["std_msgs/msg/String"]
    finally:
        stop_peer(proc)
        side.close()
        session.close()
        router.close()


def test_by_fields_types_name_standard_types_and_never_redefine_them():
    """A fleet type by its fields may hold a standard type; the standard types themselves (a
    service's request too) are not redefined by their fields, which the store would refuse."""
    for package in ("std_srvs", "rcl_interfaces"):
        srv = load_interface(package, "srv")
        for name in srv.__all__:
            getattr(srv, name)  # registers every request and response

    @message("my_robot_msgs/StampedNote")
    class StampedNote:
        stamp: Time = Time()
        note: str = ""

    interfaces = fleet_interfaces()
    assert interfaces.ros_type("my_robot_msgs/StampedNote") == "my_robot_msgs/msg/StampedNote"
    assert interfaces.definitions["my_robot_msgs/msg/StampedNote"] == \
        "builtin_interfaces/Time stamp\nstring note\n"
    data = msgpack.unpackb(encode(StampedNote(Time(sec=3, nanosec=4), "hi")))["data"]
    fields = interfaces.fields("my_robot_msgs/StampedNote", data)
    cdr = interfaces.types.encode("my_robot_msgs/msg/StampedNote", fields)
    assert interfaces.types.decode("my_robot_msgs/msg/StampedNote", cdr) == {
        "stamp": {"sec": 3, "nanosec": 4}, "note": "hi"}


def test_a_launched_fleet_shows_its_twist_to_a_ros2_peer(tmp_path):
    """`launch` with a `ros2:` section: the driver's geometry_msgs/Twist on /odom_twist reaches
    zenoh-ros2-sdk under rosidl's name and hash; the mapping maps nothing."""
    port = free_port()
    scenario = tmp_path / "twist.yaml"
    scenario.write_text(yaml.safe_dump({
        "name": "twist_ros2", "nodes": [{"name": "driver", "class": f"{NODES}:Driver"}],
        "ros2": {"router": f"tcp/127.0.0.1:{port}", "mapping": f"{NODES}:MapsNothing"}}))
    router = zenoh.open(zenoh_config(listen=[f"tcp/127.0.0.1:{port}"], mode="router"))
    launcher = subprocess.Popen([sys.executable, "-m", "twinfleet", "launch", str(scenario),
                                 "--timeout", "60"], stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True, env=child_env(),
                                start_new_session=True)
    output: list[str] = []
    threading.Thread(target=lambda: output.extend(launcher.stdout), daemon=True).start()
    peer = None
    try:
        peer = start_peer("sdk_twist_peer.py", port, "/odom_twist")
        events: queue.Queue = queue.Queue()
        read_events(peer, events)
        assert wait_event(events, "ready")["twist_hash"] == _rosidl_hash("geometry_msgs", "Twist")
        heard = wait_event(events, "twist", timeout=40)
        assert heard["linear"] == [0.5, 0.0, 0.0] and heard["angular_z"] == -0.25, output
    finally:
        stop_peer(peer)
        if launcher.poll() is None:
            launcher.send_signal(signal.SIGINT)
            try:
                launcher.wait(timeout=15)
            except subprocess.TimeoutExpired:
                os.killpg(launcher.pid, signal.SIGKILL)
        router.close()
