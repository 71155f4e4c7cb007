"""Coroutine callbacks suspended across awaits while other callbacks run.

`Stepper` awaits two calls in one async timer callback and keeps the first response in
a local variable across the second await; the server pokes it (a topic) while it
serves the first request, and the poke's callback (a reentrant group) changes the
node's state while the coroutine is suspended. `Tally` runs two async timer callbacks
in a reentrant group that each read a total, await a call and write the total + 1:
the classic lost update, which real rclpy shows and the checker finds.
"""

from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from std_msgs.msg import String
from std_srvs.srv import Trigger


class Pinger(Node):
    def __init__(self):
        super().__init__("pinger")
        self.served = 0
        self.poke = self.create_publisher(String, "poke", 10)
        self.create_service(Trigger, "ping", self.on_ping)

    def on_ping(self, request, response):
        self.served += 1
        if self.served == 1:
            self.poke.publish(String(data="poke"))
        response.success = True
        response.message = f"pong {self.served}"
        return response


class Stepper(Node):
    def __init__(self):
        super().__init__("stepper")
        group = ReentrantCallbackGroup()
        self.log = []
        self.client = self.create_client(Trigger, "ping", callback_group=group)
        self.create_subscription(String, "poke", self.on_poke, 10, callback_group=group)
        self.timer = self.create_timer(0.1, self.run, callback_group=group)

    async def run(self):
        self.timer.cancel()
        self.log.append("start")
        first = await self.client.call_async(Trigger.Request())
        self.log.append(first.message)
        second = await self.client.call_async(Trigger.Request())
        self.log.append(f"{first.message} then {second.message}")

    def on_poke(self, msg):
        self.log.append(msg.data)


class Tally(Node):
    def __init__(self):
        super().__init__("tally")
        group = ReentrantCallbackGroup()
        self.total = 0
        self.finished = 0
        self.client = self.create_client(Trigger, "ping", callback_group=group)
        self.a = self.create_timer(0.1, self.bump_a, callback_group=group)
        self.b = self.create_timer(0.1, self.bump_b, callback_group=group)

    async def bump_a(self):
        self.a.cancel()
        await self.bump()

    async def bump_b(self):
        self.b.cancel()
        await self.bump()

    async def bump(self):
        seen = self.total
        await self.client.call_async(Trigger.Request())
        self.total = seen + 1
        self.finished += 1


class Gate(Node):
    """A coroutine holds the default group while a timer and a sample become ready; when it
    ends, both run, in an order rclpy does not promise."""

    def __init__(self):
        super().__init__("gate")
        self.order = []
        self.client = self.create_client(Trigger, "ping", callback_group=ReentrantCallbackGroup())
        self.create_subscription(String, "poke", self.on_poke, 10)
        self.first = self.create_timer(0.1, self.run)
        self.second = self.create_timer(0.1, self.other)

    async def run(self):
        self.first.cancel()
        await self.client.call_async(Trigger.Request())
        self.order.append("run")

    def other(self):
        self.second.cancel()
        self.order.append("other")

    def on_poke(self, msg):
        self.order.append("poke")


def main():
    import sys

    import oracle_main

    node = Tally if "tally" in sys.argv else Gate if "gate" in sys.argv else Stepper
    oracle_main.run([Pinger, node], ["log", "total", "finished", "order"],
                    done=lambda nodes: len(getattr(nodes[1], "log", ())) >= 4
                    or getattr(nodes[1], "finished", 0) >= 2
                    or len(getattr(nodes[1], "order", ())) >= 3, timeout_s=3.0,
                    wait_publishers=node is not Tally)


if __name__ == "__main__":
    main()
