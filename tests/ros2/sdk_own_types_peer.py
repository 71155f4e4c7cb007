"""An independent ROS 2 peer for tests/ros2/test_bridge_without_mapping.py: zenoh-ros2-sdk
(not ours) in its own process, its message definitions read from a folder the test wrote by
hand (``<pkg>/msg/<Name>.msg``).

Usage: python sdk_own_types_peer.py PORT MSG_DIR TOPIC TYPE. It prints the ROS graph's topics
and the first sample of TOPIC (decoded as TYPE by the SDK), one JSON line each, and exits.
"""

import json
import sys
import threading

from zenoh_ros2_sdk import discovery
from zenoh_ros2_sdk.message_registry import get_registry
from zenoh_ros2_sdk.subscriber import ROS2Subscriber

port, folder, topic, msg_type = int(sys.argv[1]), sys.argv[2], sys.argv[3], sys.argv[4]
get_registry(folder)
topics = discovery.get_topic_names_and_types(router_port=port, timeout=1.0)
print(json.dumps({"event": "topics", "topics": [[t, types] for t, types in topics]}), flush=True)
got = threading.Event()


def on_sample(m):
    if not got.is_set():
        fields = {k: getattr(m, k) for k in ("x", "y", "theta", "name")}
        print(json.dumps({"event": "sample", **fields}), flush=True)
        got.set()


sub = ROS2Subscriber(topic, msg_type, router_port=port, callback=on_sample)
got.wait(30)
sub.close()
