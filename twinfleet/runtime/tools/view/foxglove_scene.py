"""Fleet samples as Foxglove's well-known messages, for the live bridge and for exports.

`FoxgloveScene.feed(topic, envelope, now_ns)` turns one decoded envelope
(read with plain msgpack, as `runtime.tools.view.viewstate` does: no node code is
imported) into ``(channel topic, foxglove message)`` pairs. Everything lives
in one frame, ``map``: x grows with the grid column, y with the grid row, one
cell is the map's resolution (metres), offset by the map's origin; so
Foxglove's 3D panel draws the map and the robots with no transform and no
configuration.

    /foxglove/map              foxglove.Grid         from /map (twinfleet_msgs/OccupancyGrid):
                                                     an ``occupancy`` uint8 field, 100 occupied
    /foxglove/robots           foxglove.SceneUpdate  one entity per robot: its shadow (a cube the
                                                     size of the robot footprint, turned to its
                                                     heading), a heading arrow, its name, its
                                                     trail so far and its planned path
    /foxglove/<robot>/scan     foxglove.PointCloud   from /<robot>/scan: the cells the LIDAR hit
    /foxglove/collisions       foxglove.SceneUpdate  one red entity per collision: both cells
                                                     and the line between them

Directions 0..7 step 45° from +row (0) towards +column (2), as in
`nodes.msgs`; in the ``map`` frame heading d has yaw ``pi/2 - d*pi/4``.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Mapping
from typing import Any, final

from foxglove.messages import (
    ArrowPrimitive,
    Color,
    CubePrimitive,
    Grid,
    LinePrimitive,
    LinePrimitiveLineType,
    PackedElementField,
    PackedElementFieldNumericType,
    Point3,
    PointCloud,
    Pose,
    Quaternion,
    SceneEntity,
    SceneUpdate,
    SpherePrimitive,
    TextPrimitive,
    Timestamp,
    Vector2,
    Vector3,
)

FRAME = "map"
PREFIX = "/foxglove"
MAP_TOPIC, ROBOTS_TOPIC, COLLISIONS_TOPIC = f"{PREFIX}/map", f"{PREFIX}/robots", f"{PREFIX}/collisions"
HALF_M = 0.22  # half the robot's footprint incl. its margin (twinfleet/nodes/render.py's default)
MAX_TRAIL = 5000
PALETTE = [(220, 40, 40), (40, 90, 220), (30, 160, 60), (240, 140, 20), (150, 60, 190),
           (0, 170, 170), (200, 0, 120), (120, 120, 0)]  # the web viewer's colours


def scan_topic(robot: str) -> str:
    """The Foxglove channel of a robot's scan."""
    return f"{PREFIX}/{robot}/scan"


def _colour(index: int, alpha: float = 1.0, lighten: float = 0.0) -> Color:
    r, g, b = (c + (255 - c) * lighten for c in PALETTE[index % len(PALETTE)])
    return Color(r=r / 255, g=g / 255, b=b / 255, a=alpha)


def _yaw(direction: int) -> Quaternion:
    yaw = math.pi / 2 - (direction % 8) * math.pi / 4
    return Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))


def _stamp(now_ns: int) -> Timestamp:
    return Timestamp(now_ns // 1_000_000_000, now_ns % 1_000_000_000)


@final
class FoxgloveScene:
    """The latest fleet picture, and its Foxglove messages (module docstring)."""

    def __init__(self) -> None:
        self.resolution, self.origin = 1.0, (0.0, 0.0)
        self.order: list[str] = []
        self.poses: dict[str, Mapping[str, Any]] = {}
        self.trails: dict[str, list[tuple[int, int]]] = {}
        self.paths: dict[str, list[tuple[int, int]]] = {}
        self.collisions = 0
        self.grid: Grid | None = None

    def xy(self, cell: Any) -> tuple[float, float]:
        """Centre of grid cell (row, col) in the ``map`` frame."""
        row, col = int(cell[0]), int(cell[1])
        return (self.origin[0] + (col + 0.5) * self.resolution,
                self.origin[1] + (row + 0.5) * self.resolution)

    def _point(self, cell: Any, z: float = 0.05) -> Point3:
        x, y = self.xy(cell)
        return Point3(x=x, y=y, z=z)

    def feed(self, topic: str, env: Mapping[str, Any], now_ns: int) -> list[tuple[str, Any]]:
        """The Foxglove messages one envelope on `topic` makes (often none)."""
        kind, data = env.get("type"), env.get("data")
        if not isinstance(data, Mapping):
            return []
        if kind == "twinfleet_msgs/OccupancyGrid":
            return [(MAP_TOPIC, self._grid(data, now_ns))]
        robot = data.get("robot") if isinstance(data.get("robot"), str) else None
        if kind == "twinfleet_msgs/RobotPose" and robot and _is_cell(data.get("cell")):
            self._track(robot, data)
            return [(ROBOTS_TOPIC, SceneUpdate(entities=[self._entity(robot, now_ns)]))]
        if kind == "twinfleet_msgs/ObstacleScan" and robot:
            return [(scan_topic(robot), self._cloud(data.get("cells") or [], now_ns))]
        if kind == "twinfleet_msgs/Path" and topic.count("/") == 2 and topic.endswith("/path"):
            name = topic.split("/")[1]
            self.paths[name] = [tuple(c) for c in data.get("cells") or [] if _is_cell(c)]
            if name in self.poses:
                return [(ROBOTS_TOPIC, SceneUpdate(entities=[self._entity(name, now_ns)]))]
        if kind == "twinfleet_msgs/Collision" and _is_cell(data.get("cell_a")) \
                and _is_cell(data.get("cell_b")):
            return [(COLLISIONS_TOPIC, SceneUpdate(entities=[self._collision(data, now_ns)]))]
        return []

    def _grid(self, data: Mapping[str, Any], now_ns: int) -> Grid:
        width, height = int(data.get("width", 0)), int(data.get("height", 0))
        self.resolution = float(data.get("resolution") or 1.0)
        origin = data.get("origin") or (0.0, 0.0, 0.0)
        self.origin = (float(origin[0]), float(origin[1]))
        raw = bytes(data.get("data") or b"")
        self.grid = Grid(
            timestamp=_stamp(now_ns), frame_id=FRAME,
            pose=Pose(position=Vector3(x=self.origin[0], y=self.origin[1], z=0.0),
                      orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
            column_count=width, cell_size=Vector2(x=self.resolution, y=self.resolution),
            row_stride=width, cell_stride=1,
            fields=[PackedElementField(name="occupancy", offset=0,
                                       type=PackedElementFieldNumericType.Uint8)],
            data=raw[: width * height])
        return self.grid

    def _track(self, robot: str, data: Mapping[str, Any]) -> None:
        if robot not in self.order:
            self.order.append(robot)
            self.order.sort(key=_natural)
        self.poses[robot] = data
        trail = self.trails.setdefault(robot, [])
        cell = (int(data["cell"][0]), int(data["cell"][1]))
        if not trail or trail[-1] != cell:
            trail.append(cell)
            del trail[:-MAX_TRAIL]

    def _entity(self, robot: str, now_ns: int) -> SceneEntity:
        pose, index = self.poses[robot], self.order.index(robot)
        x, y = self.xy(pose["cell"])
        heading = _yaw(int(pose.get("direction", 0)))
        body = Pose(position=Vector3(x=x, y=y, z=0.1), orientation=heading)
        side = 2 * HALF_M
        cubes = [CubePrimitive(pose=body, size=Vector3(x=side, y=side, z=0.2),
                               color=_colour(index, 0.9))]
        arrows = [ArrowPrimitive(pose=Pose(position=Vector3(x=x, y=y, z=0.22), orientation=heading),
                                 shaft_length=side * 0.9, shaft_diameter=0.05,
                                 head_length=side * 0.4, head_diameter=0.12,
                                 color=Color(r=0.0, g=0.0, b=0.0, a=1.0))]
        lines = []
        trail = self.trails.get(robot, [])
        if len(trail) > 1:
            lines.append(LinePrimitive(type=LinePrimitiveLineType.LineStrip, thickness=0.06,
                                       points=[self._point(c, 0.02) for c in trail],
                                       color=_colour(index, 0.8, lighten=0.55)))
        ahead = self._ahead(robot, (int(pose["cell"][0]), int(pose["cell"][1])))
        if ahead:
            lines.append(LinePrimitive(type=LinePrimitiveLineType.LineStrip, thickness=0.04,
                                       points=[self._point(c, 0.04) for c in ahead],
                                       color=_colour(index, 0.8)))
        texts = [TextPrimitive(pose=Pose(position=Vector3(x=x, y=y, z=0.5),
                                         orientation=Quaternion(w=1.0)),
                               billboard=True, font_size=14, scale_invariant=True,
                               color=Color(r=0.0, g=0.0, b=0.0, a=1.0), text=robot)]
        return SceneEntity(timestamp=_stamp(now_ns), frame_id=FRAME, id=f"robot/{robot}",
                           cubes=cubes, arrows=arrows, lines=lines, texts=texts)

    def _ahead(self, robot: str, here: tuple[int, int]) -> list[tuple[int, int]]:
        """The planned path from the robot's cell on (a live plan keeps passed waypoints)."""
        path = self.paths.get(robot) or []
        if here in path:
            path = path[path.index(here) + 1:]
        return [here, *path] if path else []

    def _cloud(self, cells: Any, now_ns: int) -> PointCloud:
        points = [self.xy(c) for c in cells if _is_cell(c)]
        data = b"".join(struct.pack("<fff", x, y, 0.05) for x, y in points)
        f32 = PackedElementFieldNumericType.Float32
        return PointCloud(timestamp=_stamp(now_ns), frame_id=FRAME,
                          pose=Pose(position=Vector3(), orientation=Quaternion(w=1.0)),
                          point_stride=12,
                          fields=[PackedElementField(name=n, offset=4 * i, type=f32)
                                  for i, n in enumerate("xyz")], data=data)

    def _collision(self, data: Mapping[str, Any], now_ns: int) -> SceneEntity:
        self.collisions += 1
        red = Color(r=1.0, g=0.0, b=0.0, a=0.8)
        spheres = []
        for cell in (data["cell_a"], data["cell_b"]):
            x, y = self.xy(cell)
            spheres.append(SpherePrimitive(pose=Pose(position=Vector3(x=x, y=y, z=0.1),
                                                     orientation=Quaternion(w=1.0)),
                                           size=Vector3(x=0.6, y=0.6, z=0.6), color=red))
        line = LinePrimitive(type=LinePrimitiveLineType.LineStrip, thickness=0.08,
                             points=[self._point(data["cell_a"], 0.2),
                                     self._point(data["cell_b"], 0.2)], color=red)
        label = f"{data.get('robot_a')} × {data.get('robot_b')} at t={data.get('time_ms')} ms"
        return SceneEntity(timestamp=_stamp(now_ns), frame_id=FRAME,
                           id=f"collision/{self.collisions}", spheres=spheres, lines=[line],
                           texts=[TextPrimitive(pose=Pose(position=self._vec(data["cell_a"]),
                                                          orientation=Quaternion(w=1.0)),
                                                billboard=True, font_size=14,
                                                scale_invariant=True, color=red, text=label)])

    def _vec(self, cell: Any) -> Vector3:
        x, y = self.xy(cell)
        return Vector3(x=x, y=y, z=0.8)


def _is_cell(value: Any) -> bool:
    return isinstance(value, list | tuple) and len(value) == 2 and all(
        isinstance(v, int) and not isinstance(v, bool) for v in value)


def _natural(name: str) -> tuple[Any, ...]:
    head = name.rstrip("0123456789")
    tail = name[len(head):]
    return (head, int(tail) if tail else -1)


SCHEMAS = {MAP_TOPIC: Grid, ROBOTS_TOPIC: SceneUpdate, COLLISIONS_TOPIC: SceneUpdate}


def message_class(topic: str) -> type:
    """The foxglove message class of a channel this module writes."""
    return SCHEMAS.get(topic) or PointCloud
