"""A service whose callback asks another service before it answers: rclpy runs an
`async def` service callback as a task and replies when it returns. twinfleet's rclpy
answers a request within its own step, so each of these nodes is a contract breach
(exit 4, no verdict), never a property violation."""

from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from std_srvs.srv import SetBool, Trigger


class Backend(Node):
    def __init__(self):
        super().__init__("backend")
        self.create_service(Trigger, "backend", self.on_backend)

    def on_backend(self, request, response):
        response.success = True
        response.message = "from backend"
        return response


class Relay(Node):
    """Awaits the backend's answer inside its service callback (a deferred reply)."""

    def __init__(self):
        super().__init__("relay")
        group = ReentrantCallbackGroup()
        self.client = self.create_client(Trigger, "backend", callback_group=group)
        self.create_service(SetBool, "relay", self.on_relay, callback_group=group)

    async def on_relay(self, request, response):
        answer = await self.client.call_async(Trigger.Request())
        response.success = answer.success
        response.message = answer.message
        return response


class BusyRelay(Node):
    """Its timer awaits the backend in the default group, which its service shares: a
    request arriving meanwhile would wait for the group."""

    def __init__(self):
        super().__init__("busy_relay")
        self.client = self.create_client(Trigger, "backend",
                                         callback_group=ReentrantCallbackGroup())
        self.create_service(SetBool, "relay", self.on_relay)
        self.create_timer(0.05, self.tick)
        self.asked = False

    async def tick(self):
        if not self.asked:
            self.asked = True
            await self.client.call_async(Trigger.Request())

    def on_relay(self, request, response):
        response.success = True
        return response


class Asker(Node):
    def __init__(self):
        super().__init__("asker")
        self.got = ""
        self.sent = False
        self.client = self.create_client(SetBool, "relay")
        self.create_timer(0.05, self.tick)

    def tick(self):
        if not self.sent:
            self.sent = True
            self.client.call_async(SetBool.Request(data=True)).add_done_callback(self.done)

    def done(self, future):
        self.got = future.result().message
