"""An independent ROS 2 peer for tests/ros2/test_launched_bridge.py: zenoh-ros2-sdk (not ours)
in its own process, its message definitions read from the ros-jazzy packages' share/.

Usage: python sdk_fleet_peer.py PORT. It lists the ROS graph (the node tokens by plain Zenoh
liveliness, topics and their publishers and subscribers by the SDK), subscribes to /map
(transient local, as a late joiner), /r1/pose and /r1/scan, prints one JSON line per event,
publishes a PoseStamped on /goal_pose when told "goal X Y" on stdin, and exits on "quit".
"""

import json
import sys
import time
from pathlib import Path

import zenoh
from zenoh_ros2_sdk import discovery
from zenoh_ros2_sdk.message_registry import get_registry
from zenoh_ros2_sdk.publisher import ROS2Publisher
from zenoh_ros2_sdk.qos import QosDurability, QosProfile
from zenoh_ros2_sdk.subscriber import ROS2Subscriber

port = int(sys.argv[1])
get_registry(str(Path(sys.prefix) / "share"))


def say(**event):
    print(json.dumps(event), flush=True)


def node_names():
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    with zenoh.open(conf) as session:
        replies = session.liveliness().get("@ros2_lv/0/**", timeout=1.0)
        parts = [str(r.ok.key_expr).split("/") for r in replies if r.ok is not None]
    return sorted({p[8] for p in parts if len(p) == 9 and p[5] == "NN"})


say(event="nodes", nodes=node_names())
topics = discovery.get_topic_names_and_types(router_port=port, timeout=1.0)
say(event="topics", topics=[[t, types] for t, types in topics])
for name in ("/map", "/r1/pose", "/goal_pose"):
    info = discovery.get_topic_info(name, router_port=port, timeout=1.0, verbose=True)
    say(event="info", topic=name, publishers=[p.node_name for p in info.publishers],
        subscribers=[s.node_name for s in info.subscribers])

latched = QosProfile(durability=QosDurability.TRANSIENT_LOCAL, history_depth=1)
seen = set()


def once(kind, **event):
    if kind not in seen:
        seen.add(kind)
        say(event=kind, **event)


def on_map(m):
    once("map", width=m.info.width, height=m.info.height, resolution=m.info.resolution,
         frame=m.header.frame_id, occupied=sum(1 for v in m.data if v == 100),
         unknown=sum(1 for v in m.data if v == -1), cells=len(m.data),
         origin=[m.info.origin.position.x, m.info.origin.position.y])


subs = [
    ROS2Subscriber("/map", "nav_msgs/msg/OccupancyGrid", router_port=port, qos=latched,
                   callback=on_map),
    ROS2Subscriber("/r1/pose", "geometry_msgs/msg/PoseStamped", router_port=port,
                   callback=lambda m: once("pose", frame=m.header.frame_id,
                                           x=m.pose.position.x, y=m.pose.position.y,
                                           z=m.pose.position.z, qz=m.pose.orientation.z,
                                           qw=m.pose.orientation.w)),
    ROS2Subscriber("/r1/scan", "sensor_msgs/msg/LaserScan", router_port=port,
                   callback=lambda m: once("scan", frame=m.header.frame_id, beams=len(m.ranges),
                                           range_max=m.range_max,
                                           finite=sum(1 for r in m.ranges
                                                      if r != float("inf")))),
]
goal = ROS2Publisher("/goal_pose", "geometry_msgs/msg/PoseStamped", router_port=port)
time.sleep(0.5)  # the publisher's token reaches the router before anyone is told it is ready
say(event="ready")
for line in sys.stdin:
    words = line.split()
    if words[:1] == ["goal"]:
        T = goal.session_mgr.store.types
        pose = T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=float(words[1]), y=float(words[2]), z=0.0),
            orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0))
        header = T["std_msgs/msg/Header"](
            stamp=T["builtin_interfaces/msg/Time"](sec=1, nanosec=0), frame_id="map")
        goal.publish(header=header, pose=pose)
        say(event="goal_sent")
    elif words[:1] == ["quit"]:
        break
for s in subs:
    s.close()
goal.close()
