"""A charging station with one slot and two robots that ask for it: a system with no map.

The station answers every request `granted` while it has a free slot, but it
books the slot only when the robot reports that it plugged in: two robots
asking before either plugs in are both granted, and both plug in.
"""

from __future__ import annotations

from dataclasses import dataclass

from twinfleet import Context, Node, String, every, handler, message, service, subscribe


@message("charging/Booking")
class Booking:
    robot: str


@message("charging/Answer")
class Answer:
    granted: bool


@dataclass
class StationState:
    in_use: int = 0


class Station(Node):
    """Grants while a slot is free; counts a slot as used when a robot plugs in."""

    def initial_state(self) -> StationState:
        return StationState()

    @service("/book")
    def book(self, ctx: Context, request: Booking) -> Answer:
        return Answer(self.state.in_use < 1)

    @subscribe("/plugged")
    def on_plugged(self, ctx: Context, msg: String) -> None:
        self.state.in_use += 1


@dataclass
class RobotState:
    asked: bool = False
    charging: bool = False


class Asker(Node):
    """Asks for the slot once, on its first tick, and plugs in when granted."""

    def initial_state(self) -> RobotState:
        return RobotState()

    @every(100)
    def tick(self, ctx: Context) -> None:
        if not self.state.asked:
            self.state.asked = True
            ctx.call("/book", Booking(self.name), self.on_answer)

    @handler()
    def on_answer(self, ctx: Context, answer: Answer) -> None:
        if answer.granted:
            self.state.charging = True
            ctx.publish("/plugged", String(self.name))
