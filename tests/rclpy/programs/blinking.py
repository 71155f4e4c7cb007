"""Timers cancelled and reset: `a` ticks twice and cancels itself; `b` then resets `a`
(which ticks twice more) and cancels itself."""

from rclpy.node import Node


class Blinker(Node):
    def __init__(self):
        super().__init__("blinker")
        self.events = []
        self.canceled = []
        self.a = self.create_timer(0.1, self.on_a)
        self.b = self.create_timer(0.25, self.on_b)

    def on_a(self):
        self.events.append("a")
        if self.events.count("a") in (2, 4):
            self.a.cancel()
        if self.events.count("a") == 4:
            self.canceled = [self.a.is_canceled(), self.b.is_canceled()]

    def on_b(self):
        self.events.append("b")
        self.b.cancel()
        self.a.reset()


def main():
    import oracle_main

    oracle_main.run([Blinker], ["events", "canceled"],
                    done=lambda nodes: bool(nodes[0].canceled), timeout_s=2.0)


if __name__ == "__main__":
    main()
