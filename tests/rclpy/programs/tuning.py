"""Parameters: declared with defaults, overridden at launch, changed at run time through an
on-set callback that refuses a negative gain."""

from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter

CHANGES = {1: ("gain", 2.0), 2: ("gain", -1.0), 3: ("mode", "manual")}


class Tuner(Node):
    def __init__(self):
        super().__init__("tuner")
        self.declare_parameter("gain", 1.0)
        self.declare_parameter("mode", "auto")
        self.initial = [self.get_parameter("gain").value, self.get_parameter("mode").value]
        self.add_on_set_parameters_callback(self.check)
        self.outcomes = []
        self.final = []
        self.step = 0
        self.timer = self.create_timer(0.1, self.tick)

    def check(self, parameters):
        for p in parameters:
            if p.name == "gain" and p.value < 0:
                return SetParametersResult(successful=False, reason="gain must be >= 0")
        return SetParametersResult(successful=True)

    def tick(self):
        self.step += 1
        if self.step not in CHANGES:
            self.timer.cancel()
            self.final = [p.value for p in self.get_parameters(["gain", "mode"])]
            return
        name, value = CHANGES[self.step]
        result = self.set_parameters([Parameter(name, value=value)])[0]
        self.outcomes.append([name, result.successful])


def main():
    import oracle_main

    oracle_main.run([Tuner], ["initial", "outcomes", "final"],
                    done=lambda nodes: bool(nodes[0].final))


if __name__ == "__main__":
    main()
