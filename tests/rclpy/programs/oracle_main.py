"""The `main()` of the conformance programs under real rclpy (never loaded by twinfleet).

Builds the program's nodes in one process, waits until every publisher has matched a
subscription (in this process or another) and every client sees its service (a sample sent
before discovery is lost), then spins until `done(nodes)` or the timeout, and prints
one line ``RESULT <json>``: the attributes each node names in `report`.
"""

import json
import sys
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor


def _wait_matched(nodes, deadline, publishers):
    pending = [p for n in nodes for p in n.publishers if publishers and p.topic_name != "/rosout"
               and not p.topic_name.endswith("/parameter_events")]
    clients = [c for n in nodes for c in n.clients]
    while time.monotonic() < deadline:
        if all(p.get_subscription_count() > 0 for p in pending) and all(
                c.service_is_ready() for c in clients):
            return
        time.sleep(0.05)
    raise SystemExit("discovery did not match in time")


def run(classes, report, done=lambda nodes: False, timeout_s=5.0, wait_publishers=True):
    """Run `classes` (node classes) until `done` or `timeout_s`; print their `report`.
    With `wait_publishers` false, no publisher waits for a subscriber (none will come)."""
    rclpy.init(args=sys.argv)
    nodes = [cls() for cls in classes]
    _wait_matched(nodes, time.monotonic() + 20.0, wait_publishers)
    executor = SingleThreadedExecutor()
    for node in nodes:
        executor.add_node(node)
    end = time.monotonic() + timeout_s
    while time.monotonic() < end and not done(nodes):
        executor.spin_once(timeout_sec=0.05)
    result = {node.get_name(): {k: getattr(node, k) for k in report if hasattr(node, k)}
              for node in nodes}
    print("RESULT " + json.dumps(result), flush=True)
    for node in nodes:
        node.destroy_node()
    rclpy.try_shutdown()
