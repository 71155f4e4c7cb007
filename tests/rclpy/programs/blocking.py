"""Blocking idioms inside callbacks, which rclpy's documentation warns against: each node
does one in a timer callback. Under twinfleet each is the contract breach (exit 4) whose
line names the idiom and what to use instead."""

import time

import rclpy
from rclpy.node import Node
from std_srvs.srv import Trigger


class BlockingCall(Node):
    def __init__(self):
        super().__init__("blocking_call")
        self.client = self.create_client(Trigger, "ping")
        self.create_timer(0.1, self.tick)

    def tick(self):
        self.client.call(Trigger.Request())


class Sleeper(Node):
    def __init__(self):
        super().__init__("sleeper")
        self.create_timer(0.1, self.tick)

    def tick(self):
        time.sleep(0.01)


class RateSleeper(Node):
    def __init__(self):
        super().__init__("rate_sleeper")
        self.rate = self.create_rate(10)
        self.create_timer(0.1, self.tick)

    def tick(self):
        self.rate.sleep()


class NestedSpinner(Node):
    def __init__(self):
        super().__init__("nested_spinner")
        self.client = self.create_client(Trigger, "ping")
        self.create_timer(0.1, self.tick)

    def tick(self):
        future = self.client.call_async(Trigger.Request())
        rclpy.spin_until_future_complete(self, future)


class Pinger(Node):
    def __init__(self):
        super().__init__("pinger")
        self.create_service(Trigger, "ping", self.on_ping)

    def on_ping(self, request, response):
        response.success = True
        return response
