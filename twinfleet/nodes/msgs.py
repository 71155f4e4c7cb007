"""Messages of the robot system.

Cells are (row, column) pairs of the occupancy grid (docs/robots.md §2);
directions are 0..7 counter-clockwise, 45° apart (0 = +row).
"""

from __future__ import annotations

from twinfleet import message

Cell = tuple[int, int]


@message("twinfleet_msgs/RobotPose")
class RobotPose:
    """A robot's report of its cell, heading and speed (the model's updateRobotLocation)."""

    robot: str
    cell: Cell
    direction: int
    velocity: int  # cells per second; 0 when standing
    done: bool = False


@message("twinfleet_msgs/ObstacleScan")
class ObstacleScan:
    """A simulated LIDAR scan: the grid cells of the first hit of each beam (absolute cells)."""

    robot: str
    cells: tuple[Cell, ...]


@message("twinfleet_msgs/PathRequest")
class PathRequest:
    """Ask the map server for a path; `final` is False for a back-off detour."""

    robot: str
    start: Cell
    goal: Cell
    final: bool = True


@message("twinfleet_msgs/Goal")
class Goal:
    """A new final goal for one robot, on its ``goal`` topic (an operator's or a ROS 2 tool's,
    through the bridge: no node of the shipped scenarios publishes it)."""

    cell: Cell


@message("twinfleet_msgs/Path")
class Path:
    """Waypoints from the start (excluded) to the goal; empty when planning failed."""

    cells: tuple[Cell, ...]


@message("twinfleet_msgs/OccupancyGrid")
class OccupancyGrid:
    """The static map: row-major bytes, 100 = occupied, 0 = free (latched on /map)."""

    width: int
    height: int
    resolution: float
    origin: tuple[float, float, float]
    data: bytes


@message("twinfleet_msgs/Collision")
class Collision:
    """Two robots' shadows intersect."""

    robot_a: str
    robot_b: str
    cell_a: Cell
    cell_b: Cell
    time_ms: int


@message("twinfleet_msgs/RobotStatus")
class RobotStatus:
    """A robot's own account of its run, published on `<ns>/status` when something changes."""

    robot: str
    mode: str  # planning | rotating | moving | waiting | backing_off | arrived | stuck
    cell: Cell
    goal: Cell
    waits: int
    failures: int
    time_ms: int


@message("twinfleet_msgs/FleetStatus")
class FleetStatus:
    """The map server's view: known robot cells and the collisions seen so far."""

    robots: tuple[str, ...]
    cells: tuple[Cell, ...]
    collisions: int
    time_ms: int
