"""A turtle on a line, in plain rclpy: a controller drives it to a goal on a timer, the
turtle (a simulated robot) moves on each command and reports its pose, a /reset service
puts it back, the controller calls it with a done callback and drives two laps, and a
safety monitor keeps the farthest pose seen. Parameters: goal and step."""

import contextlib

import rclpy
from geometry_msgs.msg import Pose2D, Twist
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from std_srvs.srv import Trigger


class Turtle(Node):
    def __init__(self):
        super().__init__("turtle")
        self.x = 0
        self.resets = 0
        self.pose = self.create_publisher(Pose2D, "pose", 10)
        self.create_subscription(Twist, "cmd_vel", self.on_cmd, 10)
        self.create_service(Trigger, "reset", self.on_reset)

    def on_cmd(self, msg):
        self.x += int(msg.linear.x)
        self.pose.publish(Pose2D(x=float(self.x)))

    def on_reset(self, request, response):
        self.x = 0
        self.resets += 1
        response.success = True
        response.message = f"reset {self.resets}"
        return response


class Controller(Node):
    def __init__(self):
        super().__init__("controller")
        self.declare_parameter("goal", 4)
        self.declare_parameter("step", 1)
        self.goal = self.get_parameter("goal").value
        self.add_on_set_parameters_callback(self.on_parameters)
        self.arrived = False
        self.laps = 0
        self.cmd = self.create_publisher(Twist, "cmd_vel", 10)
        self.create_subscription(Pose2D, "pose", self.on_pose, 10)
        self.reset = self.create_client(Trigger, "reset")
        self.timer = self.create_timer(0.1, self.tick)

    def on_parameters(self, parameters):
        for p in parameters:
            if p.name == "goal" and p.value <= 0:
                return SetParametersResult(successful=False, reason="goal must be > 0")
            if p.name == "goal":
                self.goal = p.value
        return SetParametersResult(successful=True)

    def tick(self):
        if not self.arrived:
            msg = Twist()
            msg.linear.x = float(self.get_parameter("step").value)
            self.cmd.publish(msg)

    def on_pose(self, msg):
        if msg.x >= self.goal and not self.arrived:
            self.arrived = True
            self.reset.call_async(Trigger.Request()).add_done_callback(self.on_reset_done)

    def on_reset_done(self, future):
        self.laps += 1
        self.get_logger().info(f"lap {self.laps}: {future.result().message}")
        self.arrived = self.laps >= 2


class Monitor(Node):
    def __init__(self):
        super().__init__("monitor")
        self.farthest = 0
        self.create_subscription(Pose2D, "pose", self.on_pose, 10)

    def on_pose(self, msg):
        self.farthest = max(self.farthest, int(msg.x))


def main():
    rclpy.init()
    nodes = [Turtle(), Controller(), Monitor()]
    executor = rclpy.executors.SingleThreadedExecutor()
    for node in nodes:
        executor.add_node(node)
    with contextlib.suppress(KeyboardInterrupt):
        executor.spin()
    rclpy.try_shutdown()


if __name__ == "__main__":
    main()
