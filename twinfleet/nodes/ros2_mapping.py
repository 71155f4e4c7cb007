"""The robot fleet as ROS 2 sees it: its messages in standard ROS 2 types.

``twinfleet ros2 bridge`` and ``twinfleet export --ros2`` use this table (named
``twinfleet.nodes.ros2_mapping:RobotRos2Mapping``, the default for the shipped
robot scenarios: `RobotScene.ros2`). It is plain data: each output is a
(ROS topic, ROS type ``pkg/msg/Name``, fields as nested dicts) triple, and the
framework encodes it::

    /map           OccupancyGrid  → /map               nav_msgs/msg/OccupancyGrid (latched)
    /poses         RobotPose      → /<robot>/pose      geometry_msgs/msg/PoseStamped
                                    /tf                tf2_msgs/msg/TFMessage map → <robot>/base_link
    <robot>/scan   ObstacleScan   → /<robot>/scan      sensor_msgs/msg/LaserScan in <robot>/base_link
    /<robot>/path  Path           → /<robot>/plan      nav_msgs/msg/Path

and one way in (`inbound`), for a bridge that routes a ROS 2 topic to a robot's
``goal`` (``/goal_pose=/r1/goal``: RViz's "2D Goal Pose")::

    geometry_msgs/msg/PoseStamped in frame map → <robot>/goal  Goal (the cell the point is in)

Frames follow REP 103/105: ``map`` is the fixed frame, x along the grid's
columns, y along its rows, z up; a robot's ``base_link`` faces its heading. A
grid cell (row r, column c) is the square whose corner nearest the origin is
``origin + resolution * (c, r)`` (rotated by the origin's yaw), so the grid's
row-major bytes are already ROS's row order (row 0 first, at the origin).
Occupancy keeps 0 free and 100 occupied; unknown (255 as a byte) becomes -1.

Positions need the map's resolution and origin: a pose, scan or plan that
arrives before the map gives nothing. A scan becomes a 360-beam LaserScan
(one beam a degree, from -π): each hit cell's centre, seen from the robot's
cell centre, sets the range of the beam it falls in; beams without a hit are
+inf (REP 117).

Header stamps are fleet time (the envelope's ``stamp_ms``), which starts at 0
when the fleet starts, as simulated time does.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, final

from twinfleet.nodes.msgs import Goal, ObstacleScan, OccupancyGrid, Path, RobotPose

Fields = dict[str, Any]
Output = tuple[str, str, Fields]
BEAMS = 360
UNKNOWN = 255


def _type(cls: type) -> str:
    return str(cls.__message_type__)  # type: ignore[attr-defined]


def stamp(ms: int) -> Fields:
    """builtin_interfaces/Time of a fleet time in ms."""
    return {"sec": ms // 1000, "nanosec": (ms % 1000) * 1_000_000}


def header(ms: int, frame: str) -> Fields:
    """std_msgs/Header."""
    return {"stamp": stamp(ms), "frame_id": frame}


def yaw_quaternion(yaw: float) -> Fields:
    """geometry_msgs/Quaternion of a rotation by `yaw` about z."""
    return {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)}


def heading(direction: int) -> float:
    """The yaw of direction 0..7 (`nodes.msgs`: 0 = +row, counter-clockwise, 45° apart)."""
    return math.pi / 2 - (direction % 8) * math.pi / 4


@final
class GridFrame:
    """Where the cells of the map lie in the ``map`` frame."""

    def __init__(self, resolution: float, origin: Sequence[float],
                 shape: tuple[int, int] = (0, 0)) -> None:
        self.resolution, self.shape = resolution, shape  # shape: rows, columns
        self.x0, self.y0, self.yaw0 = (float(origin[0]), float(origin[1]),
                                       float(origin[2]) if len(origin) > 2 else 0.0)

    def cell_of(self, x: float, y: float) -> tuple[int, int]:
        """The cell (row, column) a map-frame point lies in.

        Raises:
            ValueError: the point lies outside the grid.
        """
        c, s = math.cos(self.yaw0), math.sin(self.yaw0)
        dx, dy = x - self.x0, y - self.y0
        u, v = c * dx + s * dy, -s * dx + c * dy
        row, col = math.floor(v / self.resolution), math.floor(u / self.resolution)
        if not (0 <= row < self.shape[0] and 0 <= col < self.shape[1]):
            raise ValueError("outside the map")
        return (row, col)

    def centre(self, cell: Sequence[int]) -> tuple[float, float]:
        """The map-frame point at the centre of cell (row, column)."""
        u, v = (cell[1] + 0.5) * self.resolution, (cell[0] + 0.5) * self.resolution
        c, s = math.cos(self.yaw0), math.sin(self.yaw0)
        return (self.x0 + c * u - s * v, self.y0 + s * u + c * v)


@final
class RobotRos2Mapping:
    """The robot case study's messages as standard ROS 2 messages (module docstring)."""

    #: ROS topics published transient-local (late joiners get the last sample)
    latched = frozenset({"/map"})
    #: the fleet types mapped here (a bridge carries the others by their fields)
    mapped_types = frozenset(map(_type, (OccupancyGrid, RobotPose, ObstacleScan, Path)))

    def __init__(self) -> None:
        self.frame: GridFrame | None = None
        self.range_max = 100.0
        self.poses: dict[str, tuple[float, float, float]] = {}  # robot → x, y, yaw in map
        self._by_type = {_type(OccupancyGrid): self._grid, _type(RobotPose): self._pose,
                         _type(ObstacleScan): self._scan, _type(Path): self._path}

    def outbound(self, topic: str, type_name: str, data: Mapping[str, Any],
                 stamp_ms: int) -> list[Output]:
        """The ROS 2 messages one fleet message becomes; none for other types or shapes."""
        make = self._by_type.get(type_name)
        if make is None:
            return []
        try:
            return make(topic, data, stamp_ms)
        except (KeyError, IndexError, TypeError, ValueError):  # a message of another shape
            return []

    def inbound_type(self, fleet_topic: str) -> str | None:
        """The ROS 2 type a fleet topic takes from ROS 2 (a robot's ``goal``), or None."""
        return "geometry_msgs/msg/PoseStamped" if fleet_topic.endswith("/goal") else None

    def inbound(self, fleet_topic: str, ros_type: str, fields: Mapping[str, Any]) -> Goal:
        """The fleet message a checked ROS 2 message becomes on `fleet_topic`.

        Raises:
            ValueError: it cannot be one; the text is the reason it is counted under.
        """
        if self.inbound_type(fleet_topic) != ros_type:
            raise ValueError("not an inbound topic")
        if self.frame is None:
            raise ValueError("no map yet")
        if fields["header"]["frame_id"] not in ("map", "/map", ""):
            raise ValueError("not in frame map")
        position = fields["pose"]["position"]
        return Goal(self.frame.cell_of(float(position["x"]), float(position["y"])))

    def _grid(self, _topic: str, data: Mapping[str, Any], ms: int) -> list[Output]:
        width, height, res = int(data["width"]), int(data["height"]), float(data["resolution"])
        origin = data["origin"]
        cells = bytes(data["data"])
        if len(cells) != width * height or res <= 0:
            return []
        self.frame = GridFrame(res, origin, (height, width))
        self.range_max = math.hypot(width, height) * res
        occupancy = bytes(v if v != UNKNOWN else 0xFF for v in cells)  # int8 -1 is 0xFF
        pose = {"position": {"x": self.frame.x0, "y": self.frame.y0, "z": 0.0},
                "orientation": yaw_quaternion(self.frame.yaw0)}
        info = {"map_load_time": stamp(ms), "resolution": res, "width": width,
                "height": height, "origin": pose}
        return [("/map", "nav_msgs/msg/OccupancyGrid",
                 {"header": header(ms, "map"), "info": info, "data": occupancy})]

    def _pose(self, _topic: str, data: Mapping[str, Any], ms: int) -> list[Output]:
        if self.frame is None:
            return []
        robot, cell = str(data["robot"]), data["cell"]
        x, y = self.frame.centre(cell)
        yaw = heading(int(data["direction"])) + self.frame.yaw0
        self.poses[robot] = (x, y, yaw)
        position = {"x": x, "y": y, "z": 0.0}
        pose = {"header": header(ms, "map"),
                "pose": {"position": position, "orientation": yaw_quaternion(yaw)}}
        tf = {"header": header(ms, "map"), "child_frame_id": f"{robot}/base_link",
              "transform": {"translation": position, "rotation": yaw_quaternion(yaw)}}
        return [(f"/{robot}/pose", "geometry_msgs/msg/PoseStamped", pose),
                ("/tf", "tf2_msgs/msg/TFMessage", {"transforms": [tf]})]

    def _scan(self, _topic: str, data: Mapping[str, Any], ms: int) -> list[Output]:
        robot = str(data["robot"])
        where = self.poses.get(robot)
        if self.frame is None or where is None:
            return []
        increment = 2 * math.pi / BEAMS
        ranges = [math.inf] * BEAMS
        for cell in data["cells"]:
            hx, hy = self.frame.centre(cell)
            bearing = math.atan2(hy - where[1], hx - where[0]) - where[2]
            beam = round((bearing + math.pi) / increment) % BEAMS
            ranges[beam] = min(ranges[beam], math.hypot(hx - where[0], hy - where[1]))
        scan = {"header": header(ms, f"{robot}/base_link"), "angle_min": -math.pi,
                "angle_max": math.pi - increment, "angle_increment": increment,
                "time_increment": 0.0, "scan_time": 0.0, "range_min": 0.0,
                "range_max": self.range_max, "ranges": ranges, "intensities": []}
        return [(f"/{robot}/scan", "sensor_msgs/msg/LaserScan", scan)]

    def _path(self, topic: str, data: Mapping[str, Any], ms: int) -> list[Output]:
        parts = topic.split("/")
        if self.frame is None or len(parts) != 3 or parts[2] != "path":
            return []  # a path service's reply is a Path too: only /<robot>/path is a plan
        poses = []
        for cell in data["cells"]:
            x, y = self.frame.centre(cell)
            poses.append({"header": header(ms, "map"),
                          "pose": {"position": {"x": x, "y": y, "z": 0.0},
                                   "orientation": yaw_quaternion(0.0)}})
        return [(f"/{parts[1]}/plan", "nav_msgs/msg/Path",
                 {"header": header(ms, "map"), "poses": poses})]
