"""An independent ROS 2 peer for tests/ros2/test_live_bridge.py: zenoh-ros2-sdk (not ours),
run in its own process, its message definitions read from the ros-jazzy packages' share/.

Usage: python sdk_peer.py PORT. It lists topics, subscribes to /map (transient local, as a
late joiner), /r1/pose and /r1/scan, prints one JSON line per event, publishes /goal_pose
once asked on stdin ("goal"), and exits on "quit".
"""

import json
import sys
from pathlib import Path

from zenoh_ros2_sdk import discovery
from zenoh_ros2_sdk.message_registry import get_registry
from zenoh_ros2_sdk.publisher import ROS2Publisher
from zenoh_ros2_sdk.qos import QosDurability, QosProfile
from zenoh_ros2_sdk.subscriber import ROS2Subscriber

port = int(sys.argv[1])
get_registry(str(Path(sys.prefix) / "share"))


def say(**event):
    print(json.dumps(event), flush=True)


topics = discovery.get_topic_names_and_types(router_port=port, timeout=1.0)
say(event="topics", topics=[[t, types] for t, types in topics])

latched = QosProfile(durability=QosDurability.TRANSIENT_LOCAL, history_depth=1)
subs = [
    ROS2Subscriber("/map", "nav_msgs/msg/OccupancyGrid", router_port=port, qos=latched,
                   callback=lambda m: say(event="map", width=m.info.width, height=m.info.height,
                                          resolution=m.info.resolution,
                                          data=[int(v) for v in m.data[:8]])),
    ROS2Subscriber("/r1/pose", "geometry_msgs/msg/PoseStamped", router_port=port,
                   callback=lambda m: say(event="pose", frame=m.header.frame_id,
                                          x=m.pose.position.x, y=m.pose.position.y,
                                          w=m.pose.orientation.w)),
    ROS2Subscriber("/r1/scan", "sensor_msgs/msg/LaserScan", router_port=port,
                   callback=lambda m: say(event="scan", frame=m.header.frame_id,
                                          beams=len(m.ranges),
                                          finite=sorted(float(r) for r in m.ranges
                                                        if r != float("inf")))),
]
goal = ROS2Publisher("/goal_pose", "geometry_msgs/msg/PoseStamped", router_port=port)
say(event="ready")
for line in sys.stdin:
    if line.strip() == "goal":
        T = goal.session_mgr.store.types
        pose = T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=1.5, y=2.5, z=0.0),
            orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0))
        header = T["std_msgs/msg/Header"](
            stamp=T["builtin_interfaces/msg/Time"](sec=1, nanosec=0), frame_id="map")
        goal.publish(header=header, pose=pose)
        say(event="goal_sent")
    elif line.strip() == "quit":
        break
for s in subs:
    s.close()
goal.close()
