"""A service whose callback asks another service before it answers: rclpy runs an
`async def` service callback as a task and replies when it returns (twinfleet: the
request's reply is deferred, `Context.defer_reply`, and sent when the coroutine ends).

`Relay` awaits the backend inside its service callback; `EchoRelay` also says whose
request it answers, so two askers calling at once (relay_two.yaml) each get their own
answer whatever order the replies come back in; `SloppyRelay` keeps the request in an
attribute across the await, so with two requests in flight the first caller gets the
second's answer (a property violation). `BusyRelay`'s request arrives while its timer's
coroutine holds the service's group: it waits for the group and is served when it frees.
"""

import sys

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


class EchoRelay(Relay):
    """Says whose request (yes or no) each answer is for."""

    async def on_relay(self, request, response):
        answer = await self.client.call_async(Trigger.Request())
        response.success = answer.success
        response.message = f"{answer.message} ({'yes' if request.data else 'no'})"
        return response


class SloppyRelay(Relay):
    """Keeps the request in an attribute across the await: a later request overwrites it."""

    async def on_relay(self, request, response):
        self.last = request
        answer = await self.client.call_async(Trigger.Request())
        response.success = answer.success
        response.message = f"{answer.message} ({'yes' if self.last.data else 'no'})"
        return response


class BusyRelay(Node):
    """Its timer awaits the backend in the default group, which its service shares: a
    request arriving meanwhile waits for the group."""

    def __init__(self):
        super().__init__("busy_relay")
        self.client = self.create_client(Trigger, "backend",
                                         callback_group=ReentrantCallbackGroup())
        self.create_service(SetBool, "relay", self.on_relay)
        self.create_timer(0.05, self.tick)
        self.asked = False
        self.heard = ""

    async def tick(self):
        if not self.asked:
            self.asked = True
            answer = await self.client.call_async(Trigger.Request())
            self.heard = answer.message

    def on_relay(self, request, response):
        response.success = True
        response.message = f"busy relay heard {self.heard!r}"
        return response


class Asker(Node):
    def __init__(self, name="asker", data=True):
        super().__init__(name)
        self.got = ""
        self.sent = False
        self.data = data
        self.client = self.create_client(SetBool, "relay")
        self.create_timer(0.05, self.tick)

    def tick(self):
        if not self.sent:
            self.sent = True
            request = SetBool.Request(data=self.data)
            self.client.call_async(request).add_done_callback(self.done)

    def done(self, future):
        self.got = future.result().message


class OtherAsker(Asker):
    def __init__(self):
        super().__init__("other_asker", data=False)


def main():
    import oracle_main

    relay = {"echo": EchoRelay, "busy": BusyRelay}.get(sys.argv[1] if len(sys.argv) > 1
                                                      else "", Relay)
    askers = [Asker, OtherAsker] if relay is EchoRelay else [Asker]
    oracle_main.run([Backend, relay, *askers], ["got"],
                    done=lambda nodes: all(n.got for n in nodes[2:]), timeout_s=5.0)


if __name__ == "__main__":
    main()
