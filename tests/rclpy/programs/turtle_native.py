"""turtle_system.py written with twinfleet's own node API: the same behaviour, for the
benchmark that compares the two (benchmarks/rclpy_overhead.py): both check to the same
number of states."""

from dataclasses import dataclass

from twinfleet import Context, Empty, Node, String, every, handler, message, service, subscribe


@message("turtle_native/Cmd")
class Cmd:
    step: float = 0.0


@message("turtle_native/Pose")
class Pose:
    x: float = 0.0


@dataclass
class TurtleState:
    x: int = 0
    resets: int = 0


class Turtle(Node):
    def initial_state(self) -> TurtleState:
        return TurtleState()

    @subscribe("cmd_vel")
    def on_cmd(self, ctx: Context, msg: Cmd) -> None:
        self.state.x += int(msg.step)
        ctx.publish("pose", Pose(float(self.state.x)))

    @service("reset")
    def on_reset(self, ctx: Context, request: Empty) -> String:
        self.state.x = 0
        self.state.resets += 1
        return String(f"reset {self.state.resets}")


@dataclass(frozen=True)
class ControllerParams:
    goal: int = 4
    step: int = 1


@dataclass
class ControllerState:
    goal: int
    arrived: bool = False
    laps: int = 0


class Controller(Node):
    Params = ControllerParams

    def initial_state(self) -> ControllerState:
        return ControllerState(self.params.goal)

    @every(100)
    def tick(self, ctx: Context) -> None:
        if not self.state.arrived:
            ctx.publish("cmd_vel", Cmd(float(self.params.step)))

    @subscribe("pose")
    def on_pose(self, ctx: Context, msg: Pose) -> None:
        if msg.x >= self.state.goal and not self.state.arrived:
            self.state.arrived = True
            ctx.call("reset", Empty(), self.on_reset_done)

    @handler
    def on_reset_done(self, ctx: Context, reply: String) -> None:
        self.state.laps += 1
        ctx.log(f"lap {self.state.laps}: {reply.data}")
        self.state.arrived = self.state.laps >= 2


@dataclass
class MonitorState:
    farthest: int = 0


class Monitor(Node):
    def initial_state(self) -> MonitorState:
        return MonitorState()

    @subscribe("pose")
    def on_pose(self, ctx: Context, msg: Pose) -> None:
        self.state.farthest = max(self.state.farthest, int(msg.x))
