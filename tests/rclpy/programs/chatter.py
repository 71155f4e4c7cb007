"""A talker and a listener: the talker counts up on a timer, the listener keeps what it heard.

Runs as written under real rclpy (``python chatter.py talker|listener``) and under
twinfleet (a scenario names ``chatter:Talker`` and ``chatter:Listener``).
"""

import sys

from rclpy.node import Node
from std_msgs.msg import String


class Talker(Node):
    def __init__(self):
        super().__init__("talker")
        self.declare_parameter("limit", 3)
        self.limit = self.get_parameter("limit").value
        self.sent = 0
        self.pub = self.create_publisher(String, "chatter", 10)
        self.timer = self.create_timer(0.1, self.tick)

    def tick(self):
        if self.sent >= self.limit:
            self.timer.cancel()
            return
        self.sent += 1
        self.pub.publish(String(data=f"hello {self.sent}"))
        self.get_logger().info(f"sent {self.sent}")


class Listener(Node):
    def __init__(self):
        super().__init__("listener")
        self.heard = []
        self.create_subscription(String, "chatter", self.on_chatter, 10)

    def on_chatter(self, msg):
        self.heard.append(msg.data)
        self.get_logger().info(f"heard {msg.data!r}")


def main():
    import oracle_main

    which = [{"talker": Talker, "listener": Listener}[a] for a in sys.argv[1:] if not a.startswith("-")
             and a in ("talker", "listener")]
    oracle_main.run(which or [Talker, Listener], ["sent", "heard"],
                    done=lambda nodes: any(len(getattr(n, "heard", ())) >= 3 for n in nodes))


if __name__ == "__main__":
    main()
