"""An independent ROS 2 peer for tests/ros2/test_standard_types_bridge.py: zenoh-ros2-sdk (not
ours) in its own process, its definitions and hashes computed from the ros-jazzy packages'
share/.

Usage: python sdk_twist_peer.py PORT [TOPIC]. It subscribes to TOPIC (default /cmd_vel;
geometry_msgs/msg/Twist) and /status (std_msgs/msg/String), prints one JSON line per event (its own type hash once,
then each message it decodes), lists the topics once asked on stdin ("topics"), and exits
on "quit".
"""

import json
import sys
from pathlib import Path

from zenoh_ros2_sdk import discovery
from zenoh_ros2_sdk.message_registry import get_registry
from zenoh_ros2_sdk.subscriber import ROS2Subscriber

port = int(sys.argv[1])
twist_topic = sys.argv[2] if len(sys.argv) > 2 else "/cmd_vel"
get_registry(str(Path(sys.prefix) / "share"))


def say(**event):
    print(json.dumps(event), flush=True)


twist = ROS2Subscriber(twist_topic, "geometry_msgs/msg/Twist", router_port=port,
                       callback=lambda m: say(event="twist", linear=[m.linear.x, m.linear.y,
                                                                     m.linear.z],
                                              angular_z=m.angular.z))
text = ROS2Subscriber("/status", "std_msgs/msg/String", router_port=port,
                      callback=lambda m: say(event="string", data=m.data))
say(event="ready", twist_hash=twist.type_hash, string_hash=text.type_hash)
for line in sys.stdin:
    if line.strip() == "topics":
        topics = discovery.get_topic_names_and_types(router_port=port, timeout=1.0)
        say(event="topics", topics=[[t, types] for t, types in topics])
    elif line.strip() == "quit":
        break
twist.close()
text.close()
