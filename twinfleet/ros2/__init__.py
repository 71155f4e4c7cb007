"""The ROS 2 bridge: a twinfleet fleet as rmw_zenoh's ROS 2 nodes see it (docs/ros2.md).

A layer beside the runtime: it may import the runtime's host, fleet, tools,
contract and scenario wings; only the command line and the testing API import
it, and only it imports the ROS field's libraries (rosbags, mcap-ros2-support),
installed with the ``twinfleet[ros2]`` extra.

Modules: `wire` (rmw_zenoh's keys, liveliness tokens, QoS strings, attachments,
sans I/O), `cdr` (messages as plain values ↔ CDR),
`mapping` (a fleet's ROS 2 mapping by import name), `interfaces` (the other
fleet types by their fields, and their package), `graph` (the bridge's ROS
nodes and endpoints, inbound checks, sans I/O), `bridge` (the ROS 2 session),
`live` (a running fleet bridged: `ros2 bridge`, `launch --ros2`), `graph_list`
(the ROS 2 graph for `node list` / `topic list`), `rosbag` (recordings as
rosbag2 folders), `commands` (the command line).
"""

__all__ = ["bridge", "cdr", "commands", "graph", "graph_list", "interfaces", "live", "mapping",
           "rosbag", "wire"]
