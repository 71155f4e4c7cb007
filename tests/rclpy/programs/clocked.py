"""Time, Duration, to_msg, a std_msgs Header, a logger below its level, and rclpy.qos reached
as an attribute of a bare `import rclpy`."""

import rclpy
from rclpy.duration import Duration
from rclpy.node import Node
from std_msgs.msg import Header


class Clocked(Node):
    def __init__(self):
        super().__init__("clocked")
        self.stamps = []
        self.qos_depth = rclpy.qos.qos_profile_sensor_data.depth
        self.create_timer(0.25, self.tick)

    def tick(self):
        now = self.get_clock().now()
        header = Header(stamp=now.to_msg(), frame_id="map")
        later = now + Duration(seconds=0.5)
        self.stamps.append([header.stamp.sec, header.stamp.nanosec, later.nanoseconds])
        self.get_logger().debug("not shown")
        self.get_logger().warning(f"tick at {now.nanoseconds}")
