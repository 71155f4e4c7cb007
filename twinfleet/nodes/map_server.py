"""The map server node: map, path service, simulated LIDAR, tracking, collision detection.

Message structure follows the paper's model (docs/robots.md §1) so that the
checker's `rebeca` semantics sees the same events: one self-timer per robot
re-arming every scan period (priority 1), the path service (priority 3) and
pose reports (priority 5). Robots never talk to each other.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from twinfleet import (
    QOS_LATCHED,
    Context,
    Node,
    QoS,
    String,
    file_param,
    handler,
    on_start,
    service,
    subscribe,
)
from twinfleet.nodes.geometry import shadows_intersect
from twinfleet.nodes.grid import Cell, Dims
from twinfleet.nodes.mapfile import static_grids
from twinfleet.nodes.msgs import (
    Collision,
    FleetStatus,
    ObstacleScan,
    OccupancyGrid,
    Path,
    PathRequest,
    RobotPose,
)
from twinfleet.nodes.planning import OtherRobot, PathPlanner
from twinfleet.nodes.profile import profile_named
from twinfleet.nodes.scan import Scanner, build_tables

UNKNOWN: Cell = (-1, -1)
#: The most robots one map server tracks: the depth of its /poses queue, so that one pose of
#: every robot may wait at once and none is lost to KEEP_LAST (Rule 6 of the checker).
MAX_ROBOTS = 100
SHUTDOWN_TOPIC = "/twinfleet/shutdown"


@dataclass(frozen=True)
class MapServerParams:
    """Parameters of the map server (defaults: docs/robots.md §8)."""

    robots: tuple[str, ...]
    # After the fields without a default: a type checker reads file_param() as one.
    map: str = file_param()  # the map YAML, relative to the scenario file
    profile: str = "fixed"
    scan_rate_ms: int = 100
    fov_deg: float = 180.0
    angle_inc_deg: float = 2.0
    max_range_m: float = 10.0
    robot_length: float = 0.4
    robot_width: float = 0.4
    safe_margin: float = 0.02
    stop_zone: float = 0.3
    collision_margin: float = 0.02


@dataclass
class MapServerState:
    """What the map server knows: last reported pose per robot and the collision count."""

    cells: tuple[Cell, ...]
    dirs: tuple[int, ...]
    velocities: tuple[int, ...]
    done: tuple[bool, ...]
    collisions: int = 0
    collided: tuple[tuple[str, str], ...] = field(default_factory=tuple)
    finished: bool = False


class MapServer(Node):
    """Serves the map and paths, scans for every robot, and watches for collisions."""

    Params = MapServerParams
    tool_topics = ("/map", "/fleet_status", "/collisions")  # for viewers and the run report
    publications = {"/map": QOS_LATCHED}

    def configure(self) -> None:
        p = self.params
        if not p.robots:
            raise ValueError(f"{self.name}: params.robots must name at least one robot")
        if len(p.robots) > MAX_ROBOTS:
            raise ValueError(f"{self.name}: params.robots names {len(p.robots)} robots; one "
                             f"map server tracks at most {MAX_ROBOTS}")
        if p.scan_rate_ms <= 0:
            raise ValueError(f"{self.name}: params.scan_rate_ms must be > 0, got {p.scan_rate_ms}")
        self.profile = profile_named(p.profile)
        self.map, self.static, self.inflated = static_grids(p.map, p.profile)
        self.dims = Dims(res=self.map.resolution, length=p.robot_length, width=p.robot_width,
                         safe_margin=p.safe_margin, stop_zone=p.stop_zone,
                         collision_margin=p.collision_margin)
        tables = build_tables(self.profile, p.fov_deg, p.max_range_m, p.angle_inc_deg, self.map.resolution)
        self.scanner = Scanner(self.static, tables)
        self.index = {name: i for i, name in enumerate(p.robots)}
        self.planner = PathPlanner(self.inflated, self.static, self.dims, self.profile)

    def initial_state(self) -> MapServerState:
        n = len(self.params.robots)
        return MapServerState(cells=(UNKNOWN,) * n, dirs=(0,) * n, velocities=(0,) * n,
                              done=(False,) * n)

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.publish("/map", self._grid_message())
        for robot in self.params.robots:
            ctx.after(0, self.scan_robot, robot)

    @handler(priority=1)
    def scan_robot(self, ctx: Context, robot: str) -> None:
        """One LIDAR scan for `robot`, from positions as they are now; re-armed every period."""
        i = self.index[robot]
        st = self.state
        others = [c for j, c in enumerate(st.cells) if j != i and c != UNKNOWN]
        cells = self.scanner.scan(st.cells[i], st.dirs[i], others)
        ctx.publish(f"/{robot}/scan", ObstacleScan(robot, cells))
        ctx.after(self.params.scan_rate_ms, self.scan_robot, robot)

    # Commutes: it reads the state and changes nothing, and each reply goes to its caller.
    @service("/generate_path", priority=3, commutes=True)
    def generate_path(self, ctx: Context, req: PathRequest) -> Path:
        """Plan on the static map inflated by one cell plus the other robots
        (docs/robots.md §3)."""
        i = self.index.get(req.robot, -1)
        st = self.state
        others = [OtherRobot(st.cells[j], st.dirs[j], st.velocities[j])
                  for j in range(len(st.cells)) if j != i and st.cells[j] != UNKNOWN]
        return Path(self.planner.plan(others, (req.start[0], req.start[1]), (req.goal[0], req.goal[1])))

    # KEEP_LAST MAX_ROBOTS: a pose of every robot may wait here at once (with the default 10,
    # a fleet of more than 10 robots reporting together would lose poses, live and checked).
    # Commutes: a pose writes its robot's slot and tests it against each other robot, so two
    # poses of one instant end in the same state in either order unless one of them collides
    # (the checker checks each pair in both orders and expands the world fully where not).
    @subscribe("/poses", priority=5, qos=QoS(depth=MAX_ROBOTS), commutes=True)
    def on_pose(self, ctx: Context, msg: RobotPose) -> None:
        """Track a robot's report and test its shadow against every other robot's."""
        i = self.index.get(msg.robot)
        if i is None:
            ctx.log("unknown_robot", robot=msg.robot)
            return
        st = self.state
        st.cells = _put(st.cells, i, tuple(msg.cell))
        st.dirs = _put(st.dirs, i, msg.direction)
        st.velocities = _put(st.velocities, i, msg.velocity)
        st.done = _put(st.done, i, msg.done)
        self._test_collisions(ctx, i)
        ctx.publish("/fleet_status", FleetStatus(self.params.robots, st.cells, st.collisions, ctx.now()))
        if all(st.done) and not st.finished:
            st.finished = True
            ctx.publish(SHUTDOWN_TOPIC, String("all robots arrived"))

    def _test_collisions(self, ctx: Context, i: int) -> None:
        st = self.state
        for j, other in enumerate(st.cells):
            if j == i or (other == UNKNOWN and not self.profile.collide_unheard):
                continue
            if shadows_intersect(st.cells[i], st.dirs[i], other, st.dirs[j], self.dims, self.profile):
                a, b = self.params.robots[i], self.params.robots[j]
                st.collisions += 1
                st.collided = (*st.collided[-4:], (a, b))
                ctx.publish("/collisions", Collision(a, b, st.cells[i], other, ctx.now()))
                ctx.log("collision", robots=f"{a},{b}", cells=f"{st.cells[i]},{other}")

    def _grid_message(self) -> OccupancyGrid:
        rows, cols = self.map.shape
        data = np.where(self.static, 100, 0).astype(np.uint8).tobytes()
        x, y, theta = self.map.origin
        return OccupancyGrid(cols, rows, self.map.resolution, (x, y, theta), data)


def _put(values: tuple, i: int, value: object) -> tuple:
    return (*values[:i], value, *values[i + 1:])
