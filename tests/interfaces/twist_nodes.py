"""Native nodes that speak a standard ROS 2 type (tests/integration/test_ros_types_cli.py)."""

from __future__ import annotations

from dataclasses import dataclass, field

from twinfleet import Context, Node, handler, on_start, subscribe
from twinfleet.interfaces import contract_type

Twist = contract_type("geometry_msgs/msg/Twist")
Vector3 = contract_type("geometry_msgs/msg/Vector3")


@dataclass
class FollowerState:
    """The last forward speed heard."""

    speed: float = 0.0


class Follower(Node):
    """Logs the linear x of every Twist on /cmd_vel."""

    def initial_state(self) -> FollowerState:
        return FollowerState()

    @subscribe("/cmd_vel")
    def on_cmd(self, ctx: Context, msg: Twist) -> None:
        self.state.speed = msg.linear.x
        ctx.log("cmd", x=msg.linear.x, y=msg.linear.y)


class TwoCommands(Node):
    """Sends two Twists at start: the follower may take them in either order of arrival."""

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.publish("/cmd_vel", Twist(linear=Vector3(x=1.0)))
        ctx.publish("/cmd_vel", Twist(linear=Vector3(x=2.0)))


@dataclass
class KeeperState:
    """The last Twist heard, kept whole: a frozen message in the checker's state."""

    last: Twist = field(default_factory=Twist)
    heard: int = 0


class Keeper(Node):
    """Keeps the last Twist on /cmd_vel."""

    def initial_state(self) -> KeeperState:
        return KeeperState()

    @subscribe("/cmd_vel")
    def on_cmd(self, ctx: Context, msg: Twist) -> None:
        self.state.last = msg
        self.state.heard += 1


class Driver(Node):
    """Publishes a Twist on /odom_twist every 200 ms."""

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.after(200, self.tick)

    @handler
    def tick(self, ctx: Context) -> None:
        ctx.publish("/odom_twist", Twist(linear=Vector3(x=0.5), angular=Vector3(z=-0.25)))
        ctx.after(200, self.tick)


class MapsNothing:
    """A ROS 2 mapping that maps no type: the bridge carries the standard types by itself."""

    latched: frozenset[str] = frozenset()
    mapped_types: frozenset[str] = frozenset()

    def outbound(self, topic: str, type_name: str, data: object, stamp_ms: int) -> tuple:
        return ()
