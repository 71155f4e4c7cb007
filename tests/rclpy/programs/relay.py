"""A service whose callback asks another service before it answers: rclpy runs an
`async def` service callback as a task and replies when it returns (twinfleet: the
request's reply is deferred, `Context.defer_reply`, and sent when the coroutine ends).

`Relay` awaits the backend inside its service callback; `EchoRelay` also says whose
request it answers, so two askers calling at once (relay_two.yaml) each get their own
answer whatever order the replies come back in; `SloppyRelay` keeps the request in an
attribute across the await, so with two requests in flight the first caller gets the
second's answer (a property violation). `ShortcutRelay` answers a "no" at once and a
"yes" after the backend, so `TwiceAsker`'s two calls on one client (relay_twice.yaml)
may be answered in the other order: each reply still completes its own call's future.
`BusyRelay`'s request arrives while its timer's
coroutine holds the service's group: it waits for the group and is served when it frees.
"""

import sys
from functools import partial

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
        return self.fill(response, answer, request)

    def fill(self, response, answer, request):
        response.success = answer.success
        response.message = f"{answer.message} ({'yes' if request.data else 'no'})"
        return response


class SloppyRelay(EchoRelay):
    """Keeps the request in an attribute across the await: a later request overwrites it."""

    async def on_relay(self, request, response):
        self.last = request
        answer = await self.client.call_async(Trigger.Request())
        return self.fill(response, answer, self.last)


class ShortcutRelay(Relay):
    """Answers "no" at once and "yes" only after asking the backend."""

    async def on_relay(self, request, response):
        response.success = True
        if not request.data:
            response.message = "shortcut (no)"
            return response
        answer = await self.client.call_async(Trigger.Request())
        response.message = f"{answer.message} (yes)"
        return response


class TwiceAsker(Node):
    """Calls once with yes, then at once with no, on one client; notes the order the
    replies complete its calls in, and counts replies given to the wrong call."""

    def __init__(self):
        super().__init__("twice_asker")
        self.order = []
        self.mismatched = 0
        self.client = self.create_client(SetBool, "relay")
        self.create_timer(0.05, self.tick)

    def tick(self):
        if not self.order and not getattr(self, "sent", False):
            self.sent = True
            for data in (True, False):
                future = self.client.call_async(SetBool.Request(data=data))
                future.add_done_callback(partial(self.done, data))

    def done(self, data, future):
        self.order.append(data)
        if future.result().message.endswith("(yes)") != data:
            self.mismatched += 1


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

    variant = sys.argv[1] if len(sys.argv) > 1 else ""
    relay = {"echo": EchoRelay, "busy": BusyRelay, "twice": ShortcutRelay}.get(variant, Relay)
    askers = {"echo": [Asker, OtherAsker], "twice": [TwiceAsker]}.get(variant, [Asker])
    oracle_main.run([Backend, relay, *askers], ["got", "order", "mismatched"],
                    done=lambda nodes: all(getattr(n, "got", "") or len(getattr(n, "order", ()))
                                           == 2 for n in nodes[2:]), timeout_s=5.0)


if __name__ == "__main__":
    main()
