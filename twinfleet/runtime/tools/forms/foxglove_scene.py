"""Fleet samples as Foxglove's well-known messages, for the live bridge and for exports.

`FoxgloveScene(scene).feed(topic, envelope, now_ns)` turns one decoded envelope
(read with plain msgpack: no node code is imported) into ``(channel topic,
foxglove message)`` pairs. What is drawn comes from the fleet's scene
(`runtime.contract.scene`): the envelope's data goes to `Scene.drawings`, and
the drawings become Foxglove messages. Everything lives in one frame, ``map``:
x grows with the grid column, y with the grid row, one cell is the map's
resolution (metres), offset by the map's origin; so Foxglove's 3D panel draws
the map and the bodies with no transform and no configuration.

    /foxglove/map              foxglove.Grid         the scene's grid: an ``occupancy``
                                                     uint8 field, 100 occupied
    /foxglove/robots           foxglove.SceneUpdate  one entity per body: its shadow (a cube
                                                     the size of its footprint, turned to its
                                                     heading), a heading arrow, its name, its
                                                     trail so far and its planned path
    /foxglove/<robot>/scan     foxglove.PointCloud   a body's scan: the points its sensor hit
    /foxglove/collisions       foxglove.SceneUpdate  one red entity per collision: its points
                                                     and the line between them, its caption

A heading theta (radians from +x towards +y) is the yaw of the same name in
the ``map`` frame; a body is drawn once a drawing gives its heading. Table
rows, starts, goals and the order are the web viewer's; bodies take their
colours in the natural order of their names.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Mapping
from dataclasses import replace
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

from twinfleet.runtime.contract import scene as draw
from twinfleet.runtime.contract.scene import Body, Point, Scene

FRAME = "map"
PREFIX = "/foxglove"
MAP_TOPIC, ROBOTS_TOPIC, COLLISIONS_TOPIC = f"{PREFIX}/map", f"{PREFIX}/robots", f"{PREFIX}/collisions"
MAX_TRAIL = 5000
PALETTE = [(220, 40, 40), (40, 90, 220), (30, 160, 60), (240, 140, 20), (150, 60, 190),
           (0, 170, 170), (200, 0, 120), (120, 120, 0)]  # the web viewer's colours


def scan_topic(robot: str) -> str:
    """The Foxglove channel of a robot's scan."""
    return f"{PREFIX}/{robot}/scan"


def _colour(index: int, alpha: float = 1.0, lighten: float = 0.0) -> Color:
    r, g, b = (c + (255 - c) * lighten for c in PALETTE[index % len(PALETTE)])
    return Color(r=r / 255, g=g / 255, b=b / 255, a=alpha)


def _yaw(yaw: float) -> Quaternion:
    return Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))


def _stamp(now_ns: int) -> Timestamp:
    return Timestamp(now_ns // 1_000_000_000, now_ns % 1_000_000_000)


@final
class FoxgloveScene:
    """The latest fleet picture, and its Foxglove messages (module docstring).

    Args:
        scene: how the fleet is drawn.
    """

    def __init__(self, scene: Scene) -> None:
        self.scene = scene
        self.resolution, self.origin = 1.0, (0.0, 0.0)
        self.order: list[str] = []
        self.poses: dict[str, Body] = {}
        self.trails: dict[str, list[Point]] = {}
        self.paths: dict[str, list[Point]] = {}
        self.collisions = 0
        self.grid: Grid | None = None

    def xy(self, point: Point) -> tuple[float, float]:
        """A place in cells (`runtime.contract.scene`) in the ``map`` frame."""
        return (self.origin[0] + point[0] * self.resolution,
                self.origin[1] + point[1] * self.resolution)

    def _point(self, point: Point, z: float = 0.05) -> Point3:
        x, y = self.xy(point)
        return Point3(x=x, y=y, z=z)

    def feed(self, topic: str, env: Mapping[str, Any], now_ns: int) -> list[tuple[str, Any]]:
        """The Foxglove messages one envelope on `topic` makes (often none)."""
        kind, data = env.get("type"), env.get("data")
        if not isinstance(data, Mapping) or not isinstance(kind, str):
            return []
        out: list[tuple[str, Any]] = []
        for drawing in self.scene.drawings(topic, kind, data):
            out += self._drawn(drawing, now_ns)
        return out

    def _drawn(self, drawing: draw.Drawing, now_ns: int) -> list[tuple[str, Any]]:
        """The Foxglove messages of one drawing."""
        if isinstance(drawing, draw.Grid):
            return [(MAP_TOPIC, self._grid(drawing, now_ns))]
        if isinstance(drawing, Body):
            if not self._track(drawing):
                return []
            return [(ROBOTS_TOPIC, SceneUpdate(entities=[self._entity(drawing.name, now_ns)]))]
        if isinstance(drawing, draw.Scan):
            return [(scan_topic(drawing.name), self._cloud(drawing.points, now_ns))]
        if isinstance(drawing, draw.Plan):
            self.paths[drawing.name] = list(drawing.points)
            if drawing.name in self.poses:
                return [(ROBOTS_TOPIC, SceneUpdate(entities=[self._entity(drawing.name, now_ns)]))]
        if isinstance(drawing, draw.Collision) and drawing.points:
            return [(COLLISIONS_TOPIC, SceneUpdate(entities=[self._collision(drawing, now_ns)]))]
        return []

    def _grid(self, drawn: draw.Grid, now_ns: int) -> Grid:
        width, height = drawn.width, drawn.height
        self.resolution, self.origin = drawn.resolution, drawn.origin
        self.grid = Grid(
            timestamp=_stamp(now_ns), frame_id=FRAME,
            pose=Pose(position=Vector3(x=self.origin[0], y=self.origin[1], z=0.0),
                      orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
            column_count=width, cell_size=Vector2(x=self.resolution, y=self.resolution),
            row_stride=width, cell_stride=1,
            fields=[PackedElementField(name="occupancy", offset=0,
                                       type=PackedElementFieldNumericType.Uint8)],
            data=drawn.cells[: width * height])
        return self.grid

    def _track(self, body: Body) -> bool:
        """Keep a body's latest place; False when there is nothing to send. A body is drawn
        from its first drawing that gives its heading (its arrow shows it); one without a
        heading later moves it, its heading kept, and sends nothing if it stays put."""
        robot, known = body.name, self.poses.get(body.name)
        if body.theta is None:
            if known is None or (known.x, known.y) == (body.x, body.y):
                return False
            body = replace(body, theta=known.theta)
        if robot not in self.order:
            self.order.append(robot)
            self.order.sort(key=_natural)
        self.poses[robot] = body
        trail = self.trails.setdefault(robot, [])
        here = (body.x, body.y)
        if not trail or trail[-1] != here:
            trail.append(here)
            del trail[:-MAX_TRAIL]
        return True

    def _entity(self, robot: str, now_ns: int) -> SceneEntity:
        pose, index = self.poses[robot], self.order.index(robot)
        x, y = self.xy((pose.x, pose.y))
        heading = _yaw(pose.theta or 0.0)
        body = Pose(position=Vector3(x=x, y=y, z=0.1), orientation=heading)
        side = 2 * pose.half_m
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
        ahead = self._ahead(robot, (pose.x, pose.y))
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

    def _ahead(self, robot: str, here: Point) -> list[Point]:
        """The planned path from the robot's cell on (a live plan keeps passed waypoints)."""
        path = self.paths.get(robot) or []
        if here in path:
            path = path[path.index(here) + 1:]
        return [here, *path] if path else []

    def _cloud(self, points: tuple[Point, ...], now_ns: int) -> PointCloud:
        data = b"".join(struct.pack("<fff", *self.xy(p), 0.05) for p in points)
        f32 = PackedElementFieldNumericType.Float32
        return PointCloud(timestamp=_stamp(now_ns), frame_id=FRAME,
                          pose=Pose(position=Vector3(), orientation=Quaternion(w=1.0)),
                          point_stride=12,
                          fields=[PackedElementField(name=n, offset=4 * i, type=f32)
                                  for i, n in enumerate("xyz")], data=data)

    def _collision(self, drawn: draw.Collision, now_ns: int) -> SceneEntity:
        self.collisions += 1
        red = Color(r=1.0, g=0.0, b=0.0, a=0.8)
        spheres = []
        for point in drawn.points:
            x, y = self.xy(point)
            spheres.append(SpherePrimitive(pose=Pose(position=Vector3(x=x, y=y, z=0.1),
                                                     orientation=Quaternion(w=1.0)),
                                           size=Vector3(x=0.6, y=0.6, z=0.6), color=red))
        line = LinePrimitive(type=LinePrimitiveLineType.LineStrip, thickness=0.08,
                             points=[self._point(p, 0.2) for p in drawn.points], color=red)
        return SceneEntity(timestamp=_stamp(now_ns), frame_id=FRAME,
                           id=f"collision/{self.collisions}", spheres=spheres, lines=[line],
                           texts=[TextPrimitive(pose=Pose(position=self._vec(drawn.points[0]),
                                                          orientation=Quaternion(w=1.0)),
                                                billboard=True, font_size=14,
                                                scale_invariant=True, color=red,
                                                text=drawn.caption)])

    def _vec(self, point: Point) -> Vector3:
        x, y = self.xy(point)
        return Vector3(x=x, y=y, z=0.8)


def _natural(name: str) -> tuple[Any, ...]:
    head = name.rstrip("0123456789")
    tail = name[len(head):]
    return (head, int(tail) if tail else -1)


SCHEMAS = {MAP_TOPIC: Grid, ROBOTS_TOPIC: SceneUpdate, COLLISIONS_TOPIC: SceneUpdate}


def message_class(topic: str) -> type:
    """The foxglove message class of a channel this module writes."""
    return SCHEMAS.get(topic) or PointCloud
