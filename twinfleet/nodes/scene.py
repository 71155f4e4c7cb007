"""How the robot fleet is drawn: the scene the robot scenarios name.

``scene: twinfleet.nodes.scene:RobotScene`` in a scenario makes `twinfleet
view`, `twinfleet foxglove` and `twinfleet export` draw these messages
(`nodes.msgs`); the framework itself knows none of them::

    /map            OccupancyGrid  the grid
    /poses          RobotPose      the robot, turned to its direction; its cell and
                                   whether it arrived
    <robot>/status  RobotStatus    the robot's cell (its heading unsaid), its table line
                                   and its goal
    <robot>/scan    ObstacleScan   the cells its LIDAR hit
    /<robot>/path   Path           its current plan (only on its own path topic: the
                                   path service's replies are Paths too)
    /collisions     Collision      both cells, with who and when
    /fleet_status   FleetStatus    the robots' order

In a checker trace a node whose state has a ``cell`` is a robot: its state
gives the same drawings (heading from ``dir``, scan from ``obstacles``, plan
from ``moves``), its parameters the start and the goal; the map server's
``collided`` pairs mark the last collision at both robots' cells.

Directions 0..7 step 45° from +row (0) towards +column (2) (`nodes.msgs`):
direction d is the heading ``pi/2 - d*pi/4`` from +x (columns) towards +y (rows).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any, TypeGuard, final

from twinfleet.nodes.msgs import (
    Collision,
    FleetStatus,
    ObstacleScan,
    OccupancyGrid,
    Path,
    RobotPose,
    RobotStatus,
)
from twinfleet.runtime.contract import scene as draw

#: half the side of a robot's footprint with its safety margin (a 0.4 m robot and the map
#: server's 0.02 m margin; `nodes.render` draws the same)
HALF_M = 0.22
COLUMNS = ("mode", "cell", "goal", "waits", "failures", "arrived")


def _type(cls: type) -> str:
    return str(cls.__message_type__)  # type: ignore[attr-defined]


def is_cell(value: Any) -> TypeGuard[Sequence[int]]:
    """A (row, column) pair of ints."""
    return isinstance(value, list | tuple) and len(value) == 2 and all(
        isinstance(v, int) and not isinstance(v, bool) for v in value)


def point(cell: Sequence[int]) -> draw.Point:
    """The centre of grid cell (row, column)."""
    return (cell[1] + 0.5, cell[0] + 0.5)


def heading(direction: int) -> float:
    """The heading of direction 0..7 (module docstring)."""
    return math.pi / 2 - (direction % 8) * math.pi / 4


def cell_text(cell: Any) -> str:
    """``(row,col)``, or ``–`` for no cell."""
    return f"({cell[0]},{cell[1]})" if is_cell(cell) else "–"


def _points(cells: Any) -> tuple[draw.Point, ...]:
    return tuple(point(c) for c in cells or () if is_cell(c))


def _int(value: Any) -> TypeGuard[int]:
    return isinstance(value, int) and not isinstance(value, bool)


@final
class RobotScene:
    """The robot case study's `runtime.contract.scene.Scene` (module docstring)."""

    columns = COLUMNS
    #: what the fleet is in ROS 2 (`twinfleet ros2 bridge`, `twinfleet export --ros2`)
    ros2 = "twinfleet.nodes.ros2_mapping:RobotRos2Mapping"

    def __init__(self) -> None:
        self._by_type: dict[str, Callable[[str, Mapping[str, Any]], list[draw.Drawing]]] = {
            _type(OccupancyGrid): self._grid, _type(RobotPose): self._pose,
            _type(RobotStatus): self._status, _type(ObstacleScan): self._scan,
            _type(Path): self._path, _type(Collision): self._collision,
            _type(FleetStatus): self._order}

    def drawings(self, topic: str, type_name: str, data: Mapping[str, Any]) -> list[draw.Drawing]:
        """What one message draws (module docstring); none for an unexpected shape."""
        make = self._by_type.get(type_name)
        return make(topic, data) if make is not None else []

    @staticmethod
    def _grid(_topic: str, data: Mapping[str, Any]) -> list[draw.Drawing]:
        cells, origin = data.get("data"), data.get("origin") or (0.0, 0.0, 0.0)
        if not isinstance(cells, bytes | bytearray):
            return []
        return [draw.Grid(int(data.get("width", 0)), int(data.get("height", 0)),
                          float(data.get("resolution") or 1.0),
                          (float(origin[0]), float(origin[1])), bytes(cells))]

    @staticmethod
    def _pose(_topic: str, data: Mapping[str, Any]) -> list[draw.Drawing]:
        robot, cell = data.get("robot"), data.get("cell")
        if not isinstance(robot, str) or not is_cell(cell):
            return []
        direction = data.get("direction")
        x, y = point(cell)
        return [draw.Body(robot, x, y, heading(direction) if _int(direction) else None, HALF_M),
                draw.Row(robot, (("cell", cell_text(cell)),
                                 ("arrived", "yes" if data.get("done") else "no")))]

    @staticmethod
    def _status(_topic: str, data: Mapping[str, Any]) -> list[draw.Drawing]:
        robot, cell, goal = data.get("robot"), data.get("cell"), data.get("goal")
        if not isinstance(robot, str):
            return []
        mode = data.get("mode") if isinstance(data.get("mode"), str) else ""
        values = [("mode", mode or "–"), ("cell", cell_text(cell)), ("goal", cell_text(goal))]
        values += [(k, str(data[k])) for k in ("waits", "failures") if _int(data.get(k))]
        values.append(("arrived", "yes" if mode == "arrived" else "no"))
        out: list[draw.Drawing] = [draw.Row(robot, tuple(values))]
        if is_cell(cell):
            out.append(draw.Body(robot, *point(cell), None, HALF_M))
        if is_cell(goal):
            out.append(draw.Goal(robot, point(goal)))
        return out

    @staticmethod
    def _scan(_topic: str, data: Mapping[str, Any]) -> list[draw.Drawing]:
        robot = data.get("robot")
        return [draw.Scan(robot, _points(data.get("cells")))] if isinstance(robot, str) else []

    @staticmethod
    def _path(topic: str, data: Mapping[str, Any]) -> list[draw.Drawing]:
        parts = topic.split("/")
        if len(parts) != 3 or parts[2] != "path":  # /<robot>/path, not a service reply
            return []
        return [draw.Plan(parts[1], _points(data.get("cells")))]

    @staticmethod
    def _collision(_topic: str, data: Mapping[str, Any]) -> list[draw.Drawing]:
        a, b = data.get("cell_a"), data.get("cell_b")
        if not (is_cell(a) and is_cell(b)):
            return []
        who_a, who_b, when = data.get("robot_a"), data.get("robot_b"), data.get("time_ms")
        return [draw.Collision((point(a), point(b)),
                               f"t={when} ms {who_a}{cell_text(a)} × {who_b}{cell_text(b)}",
                               f"{who_a} × {who_b} at t={when} ms")]

    @staticmethod
    def _order(_topic: str, data: Mapping[str, Any]) -> list[draw.Drawing]:
        names = tuple(r for r in data.get("robots") or () if isinstance(r, str))
        return [draw.Order(names)] if names else []

    def state_drawings(self, states: Mapping[str, Any],
                       params: Mapping[str, Mapping[str, Any]]) -> list[draw.Drawing]:
        """The fleet in one checker state (module docstring)."""
        robots = [n for n, s in states.items() if isinstance(s, Mapping) and is_cell(s.get("cell"))]
        out: list[draw.Drawing] = [draw.Order(tuple(robots))]
        for name in robots:
            out += _robot_state(name, states[name], params.get(name) or {})
        out += _last_collision(states, robots)
        return out


def _robot_state(name: str, st: Mapping[str, Any], params: Mapping[str, Any]) -> list[draw.Drawing]:
    """A robot's drawings from its checker state and parameters."""
    cell, goal = st["cell"], params.get("goal")
    direction = st.get("dir")
    moves = st.get("moves") or ()
    out: list[draw.Drawing] = [
        draw.Body(name, *point(cell), heading(direction) if _int(direction) else None, HALF_M),
        draw.Row(name, (("mode", _mode(st)), ("cell", cell_text(cell)), ("goal", cell_text(goal)),
                        ("waits", str(st.get("waits", "–"))),
                        ("failures", str(st.get("failures", "–"))),
                        ("arrived", "yes" if st.get("done") else "no"))),
        draw.Scan(name, _points(st.get("obstacles"))),
        draw.Plan(name, _points(moves[st.get("move_idx") or 0:]))]
    if is_cell(params.get("start")):
        out.append(draw.Start(name, point(params["start"])))
    if is_cell(goal):
        out.append(draw.Goal(name, point(goal)))
    return out


def _mode(st: Mapping[str, Any]) -> str:
    """What the robot is doing, as its status would say."""
    if st.get("done"):
        return "arrived"
    if st.get("stuck"):
        return "stuck"
    if st.get("waiting"):
        return "waiting"
    moves = st.get("moves") or ()
    return "moving" if moves and (st.get("move_idx") or 0) < len(moves) else "planning"


def _last_collision(states: Mapping[str, Any], robots: list[str]) -> list[draw.Drawing]:
    """The map server's last collision, marked at both robots' cells in this state."""
    server = next((s for s in states.values() if isinstance(s, Mapping) and "collided" in s), None)
    if server is None or not server.get("collisions") or not server.get("collided"):
        return []
    cells = [states[n]["cell"] for n in server["collided"][-1] if n in robots]
    if not cells:
        return []
    label = " × ".join(cell_text(c) for c in cells)
    return [draw.Collision(tuple(point(c) for c in cells), label, label)]
