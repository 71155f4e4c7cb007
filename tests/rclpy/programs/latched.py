"""A TRANSIENT_LOCAL topic: the mapper publishes two versions of its map with depth 1;
a reader that joins later gets the last one only."""

import sys

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from std_msgs.msg import String

LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)


class Mapper(Node):
    def __init__(self):
        super().__init__("mapper")
        self.versions = 0
        self.pub = self.create_publisher(String, "map", LATCHED)
        self.timer = self.create_timer(0.1, self.tick)

    def tick(self):
        if self.versions == 2:
            self.timer.cancel()
            return
        self.versions += 1
        self.pub.publish(String(data=f"map v{self.versions}"))


class Reader(Node):
    def __init__(self):
        super().__init__("reader")
        self.maps = []
        self.create_subscription(String, "map", self.on_map, LATCHED)

    def on_map(self, msg):
        self.maps.append(msg.data)


def main():
    import oracle_main

    reader = "reader" in sys.argv
    oracle_main.run([Reader] if reader else [Mapper], ["maps", "versions"],
                    done=lambda nodes: reader and bool(nodes[0].maps), timeout_s=4.0,
                    wait_publishers=False)


if __name__ == "__main__":
    main()
