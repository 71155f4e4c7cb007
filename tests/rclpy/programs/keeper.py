"""State that rclpy code keeps besides plain values: a future as an attribute, done
callbacks that are lambdas and partials capturing values, a timer made inside a callback,
tuples, dicts and a message as attributes."""

import functools

from rclpy.node import Node
from std_msgs.msg import String
from std_srvs.srv import Trigger


class Asker(Node):
    def __init__(self):
        super().__init__("asker")
        self.client = self.create_client(Trigger, "ping")
        self.pending = None
        self.answers = {}
        self.last = String(data="none")
        self.pair = (0, "zero")
        self.rounds = 0
        self.follow_up = None
        self.create_timer(0.1, self.tick)

    def tick(self):
        if self.rounds >= 2:
            return
        if self.pending is not None and not self.pending.done():
            return
        self.rounds += 1
        self.pending = self.client.call_async(Trigger.Request())
        label = f"round {self.rounds}"
        self.pending.add_done_callback(lambda future: self.keep(label, future))
        self.pending.add_done_callback(functools.partial(self.count, self.rounds))

    def keep(self, label, future):
        self.answers[label] = future.result().message
        self.last = String(data=label)

    def count(self, round_number, future):
        self.pair = (round_number, future.result().message)
        if round_number == 2 and self.follow_up is None:
            self.follow_up = self.create_timer(0.05, self.once)

    def once(self):
        self.follow_up.cancel()
        self.last.data += " and a follow-up"


class Ponger(Node):
    def __init__(self):
        super().__init__("ponger")
        self.count = 0
        self.create_service(Trigger, "ping", self.on_ping)

    def on_ping(self, request, response):
        self.count += 1
        response.message = f"pong {self.count}"
        return response
