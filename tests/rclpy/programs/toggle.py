"""A service answered through a done callback, and the same call awaited in a coroutine.

`Switch` serves ``toggle`` (std_srvs/SetBool): it keeps the value asked for and counts
requests. `Caller` calls it three times from a timer and takes each response in a done
callback. `AwaitingCaller` awaits ``call_async`` inside an ``async def`` timer callback:
with ``reentrant:=true`` its client is in a ReentrantCallbackGroup and the three calls
complete; with ``reentrant:=false`` the client shares the timer's default (mutually
exclusive) group, the suspended callback holds the group, the response is never taken
and the node hangs after its first call, under real rclpy and under twinfleet alike.
"""

import sys

from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from std_srvs.srv import SetBool


class Switch(Node):
    def __init__(self):
        super().__init__("switch")
        self.on = False
        self.requests = 0
        self.create_service(SetBool, "toggle", self.on_toggle)

    def on_toggle(self, request, response):
        self.requests += 1
        self.on = request.data
        response.success = True
        response.message = f"{'on' if self.on else 'off'} #{self.requests}"
        return response


class Caller(Node):
    def __init__(self):
        super().__init__("caller")
        self.replies = []
        self.calls = 0
        self.client = self.create_client(SetBool, "toggle")
        self.timer = self.create_timer(0.1, self.tick)

    def tick(self):
        if self.calls == 3:
            self.timer.cancel()
            return
        self.calls += 1
        future = self.client.call_async(SetBool.Request(data=self.calls % 2 == 1))
        future.add_done_callback(self.on_response)

    def on_response(self, future):
        self.replies.append(future.result().message)


class AwaitingCaller(Node):
    def __init__(self):
        super().__init__("awaiting")
        self.declare_parameter("reentrant", True)
        group = ReentrantCallbackGroup() if self.get_parameter("reentrant").value else None
        self.replies = []
        self.calls = 0
        self.client = self.create_client(SetBool, "toggle", callback_group=group)
        self.timer = self.create_timer(0.1, self.tick)

    async def tick(self):
        if self.calls == 3:
            self.timer.cancel()
            return
        self.calls += 1
        response = await self.client.call_async(SetBool.Request(data=True))
        self.replies.append(response.message)


def main():
    import oracle_main

    caller = AwaitingCaller if "awaiting" in sys.argv else Caller
    oracle_main.run([Switch, caller], ["replies", "calls", "requests"],
                    done=lambda nodes: len(getattr(nodes[1], "replies", ())) >= 3,
                    timeout_s=3.0)


if __name__ == "__main__":
    main()
