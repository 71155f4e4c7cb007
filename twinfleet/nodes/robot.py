"""The robot node: Algorithms 1–3 of the paper as the Timed Rebeca model runs them.

Loops (docs/robots.md §1): the *motion loop* `update_moving_status` re-arms
itself after each rotation or hop; while waiting, each scan delivery
re-evaluates at once (the *waiting loop*); after `max_waiting_rounds` blocked
evaluations the robot backs off to a cell picked by `ctx.choose` and re-plans.
Handler priorities are the model's: motion 1, scan 3, new path 10.
All geometry and arithmetic live in the pure modules; this class only keeps
state and sequences the steps.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

from twinfleet import CallError, Context, Node, file_param, handler, on_start, subscribe
from twinfleet.nodes.congestion import (
    backoff_candidates,
    backoff_options,
    clamp_target,
    target_margin,
)
from twinfleet.nodes.grid import Cell, Dims, direction_between, in_bounds, is_diagonal, step
from twinfleet.nodes.mapfile import OccupancyMap, static_grids
from twinfleet.nodes.motion import (
    cells_per_second,
    check_cell_size_rule,
    check_scan_rate_rule,
    distance_to_target,
    hop_time_ms,
    max_waiting_rounds,
    rotation_time_ms,
)
from twinfleet.nodes.msgs import Goal, ObstacleScan, Path, PathRequest, RobotPose, RobotStatus
from twinfleet.nodes.profile import profile_named
from twinfleet.nodes.scan import can_hop, stepwise_free

MAX_FAILURES = 2  # a third failed plan leaves the robot stuck (the model's livelock bound)


@dataclass(frozen=True)
class RobotParams:
    """Parameters of one robot (defaults: docs/robots.md §8)."""

    start: tuple[int, int]
    goal: tuple[int, int]
    # After the fields without a default: a type checker reads file_param() as one.
    map: str = file_param()  # the map YAML, relative to the scenario file
    speed: float = 0.5  # m/s
    max_wait_ms: int = 1500
    profile: str = "fixed"
    scan_rate_ms: int = 100
    tolerance: int = 2
    initial_dir: int = 2  # the model starts every robot facing N (dir 2)
    angular_dps: float = 360.0
    robot_length: float = 0.4
    robot_width: float = 0.4
    safe_margin: float = 0.02
    stop_zone: float = 0.3
    allow_unsafe_speed: bool = False  # accept a speed that breaks Eq. 1 (the paper's C2c does)


@dataclass
class RobotState:
    """Everything a robot changes, and nothing more: no absolute times (they would break
    time-shift equivalence) and no statistics counters (they would split states the model
    merges); live statistics are counted by `nodes.report` from the published messages."""

    cell: Cell
    dir: int
    targets: tuple[Cell, ...]  # a stack; the bottom is the final goal
    moves: tuple[Cell, ...] = ()
    move_idx: int = 0
    velocity: int = 0
    distance: int = 9999
    obstacles: tuple[Cell, ...] = ()
    waiting: bool = False
    waits: int = 0
    failures: int = 0
    done: bool = False
    stuck: bool = False
    front_obstacle: int = 0  # the model's informational free hops ahead (profile switch)
    goal: Cell | None = None  # a goal received on the goal topic; None: params.goal


class Robot(Node):
    """A robot that plans through the map server, senses by scans, stops, waits and backs off."""

    Params = RobotParams
    tool_topics = ("status", "path")  # for viewers and the run report (runtime.scenario.lint)
    #: topics fed from outside the fleet (a ROS 2 tool through the bridge), not by a node:
    #: live, a sample signed with the bridge's key is accepted here only, and counted
    external_topics = ("goal",)

    def configure(self) -> None:
        p = self.params
        self.profile = profile_named(p.profile)
        occ_map, self.static, self.inflated_static = static_grids(p.map, p.profile)
        self.shape = occ_map.shape
        self.dims = Dims(res=occ_map.resolution, length=p.robot_length, width=p.robot_width,
                         safe_margin=p.safe_margin, stop_zone=p.stop_zone)
        self.default_velocity = cells_per_second(p.speed, self.dims.res, self.profile)
        self.hop_ms = (hop_time_ms(p.speed, False, self.dims.res, self.profile),
                       hop_time_ms(p.speed, True, self.dims.res, self.profile))
        self.max_rounds = max(1, max_waiting_rounds(p.max_wait_ms, p.scan_rate_ms, self.profile))
        self.margin = target_margin(self.dims, self.profile)
        self._validate(occ_map)

    def _validate(self, occ_map: OccupancyMap) -> None:
        p = self.params
        for key in ("start", "goal"):
            cell = tuple(getattr(p, key))
            if not in_bounds(cell, self.shape):
                raise ValueError(f"{self.name}: {key} {list(cell)} is outside the {self.shape[0]}x{self.shape[1]} map")
            if self.static[cell]:
                raise ValueError(f"{self.name}: {key} {list(cell)} lies inside an obstacle")
        if p.max_wait_ms <= 0 or p.scan_rate_ms <= 0 or p.tolerance < 0:
            raise ValueError(f"{self.name}: max_wait_ms and scan_rate_ms must be > 0, tolerance >= 0")
        unsafe = check_scan_rate_rule(p.speed, self.dims.res, p.scan_rate_ms, self.profile)
        if unsafe and not p.allow_unsafe_speed:
            raise ValueError(f"{self.name}: {unsafe} (set allow_unsafe_speed: true to run it anyway)")
        advice = check_cell_size_rule(self.dims.res, p.robot_length)
        if advice:
            warnings.warn(f"{self.name}: {advice}", stacklevel=2)

    def initial_state(self) -> RobotState:
        return RobotState(cell=tuple(self.params.start), dir=self.params.initial_dir, targets=())

    # -- entry points ---------------------------------------------------------

    @on_start
    def start(self, ctx: Context) -> None:
        self._set_target(ctx, tuple(self.params.goal))

    @subscribe("scan", priority=3)  # KEEP_LAST 10 (default): no checked world has more waiting
    def on_scan(self, ctx: Context, msg: ObstacleScan) -> None:
        """Keep the latest scan; while waiting, re-evaluate at once (the waiting loop)."""
        self.state.obstacles = tuple(tuple(c) for c in msg.cells)
        self._note_front_obstacle()
        if self.state.waiting:
            ctx.after(0, self.update_moving_status, True)

    @subscribe("goal", priority=10)
    def on_goal(self, ctx: Context, msg: Goal) -> None:
        """A new final goal: forget the old plan and targets, plan to it (a free cell only).

        No node of the checked scenarios publishes on ``goal``: unused, this handler adds
        no event to the model."""
        cell = (int(msg.cell[0]), int(msg.cell[1]))
        if not in_bounds(cell, self.shape) or self.static[cell]:
            return
        st = self.state
        st.goal, st.targets, st.done, st.stuck, st.failures = cell, (), False, False, 0
        self._set_target(ctx, cell)

    def final_goal(self) -> Cell:
        """The goal the robot drives to: the last one received, else its parameter."""
        return self.state.goal if self.state.goal is not None else tuple(self.params.goal)

    @handler(priority=10)
    def on_path(self, ctx: Context, reply: Path | CallError) -> None:
        """A new plan: follow it, or count a failure and back off (docs/robots.md §6)."""
        st = self.state
        self._stop(flush=True)
        cells = reply.cells if isinstance(reply, Path) else ()
        if cells:
            st.failures = max(0, st.failures - 1)
            st.moves = tuple(tuple(c) for c in cells)
            ctx.publish("path", Path(st.moves))  # for viewers; nobody listens in the checker
            st.velocity = self.default_velocity
            ctx.after(0, self.update_moving_status, True)
            self._report_status(ctx, "moving")
            return
        st.failures += 1
        if st.failures > MAX_FAILURES:
            st.stuck = True
            self._report_status(ctx, "stuck")
            return
        self._back_off(ctx)

    @handler(priority=1)
    def update_moving_status(self, ctx: Context, move_next: bool) -> None:
        """The decision step: re-plan, rotate, hop or wait (docs/robots.md §5)."""
        st = self.state
        if st.move_idx >= len(st.moves):
            self._moves_exhausted(ctx)
            return
        heading = direction_between(st.cell, st.moves[st.move_idx])
        if heading != st.dir:
            self._rotate(ctx, heading, move_next)
            return
        self._note_front_obstacle()
        if self._can_hop():
            self._hop(ctx, move_next)
        else:
            self._wait(ctx)

    # -- steps ------------------------------------------------------------------

    def _note_front_obstacle(self) -> None:
        if self.profile.track_front_obstacle:
            st, d = self.state, self.dims
            st.front_obstacle = stepwise_free(st.cell, st.dir, st.obstacles, d.res, d.width,
                                              d.safe_margin)

    def _can_hop(self) -> bool:
        st = self.state
        if not self.profile.robot_aware_stop:
            return can_hop(st.cell, st.dir, st.obstacles, self.dims)
        static = [c for c in st.obstacles if self.static[c]]
        robots = [c for c in st.obstacles if not self.static[c]]
        return can_hop(st.cell, st.dir, static, self.dims, robots)

    def _moves_exhausted(self, ctx: Context) -> None:
        st = self.state
        st.velocity = 0
        if len(st.targets) > 1:
            reached = st.cell == st.targets[-1]
        else:
            reached = st.distance <= self.params.tolerance
        if reached and st.targets:
            st.targets = st.targets[:-1]
        if st.targets:
            self._stop(flush=True)
            self._request_path(ctx, st.targets[-1])
            return
        st.done = True
        if self.profile.report_arrival_pose:
            self._report_pose(ctx)
        self._report_status(ctx, "arrived")

    def _rotate(self, ctx: Context, heading: int, move_next: bool) -> None:
        st = self.state
        st.velocity = 0
        turn_ms = rotation_time_ms(st.dir, heading, self.profile, self.params.angular_dps)
        st.dir = heading
        self._report_pose(ctx)
        ctx.after(turn_ms, self.update_moving_status, move_next)

    def _hop(self, ctx: Context, move_next: bool) -> None:
        st = self.state
        if st.velocity <= 0:
            st.velocity = self.default_velocity
        nxt = step(st.cell, st.dir)
        if in_bounds(nxt, self.shape):
            st.cell = nxt
            self._report_pose(ctx)
            st.distance = distance_to_target(st.cell, self.final_goal(), self.profile)
            if st.cell == st.moves[st.move_idx]:
                st.move_idx += 1
        was_waiting = st.waiting
        st.waits, st.waiting = 0, False
        if was_waiting:
            self._report_status(ctx, "moving")
        if move_next:
            ctx.after(self.hop_ms[is_diagonal(st.dir)], self.update_moving_status, move_next)

    def _wait(self, ctx: Context) -> None:
        st = self.state
        st.velocity = 0  # not reported: the map server keeps the last speed (docs/robots.md §5)
        if not st.waiting:
            self._report_status(ctx, "waiting")
        st.waiting = True
        st.waits += 1
        if st.waits % self.max_rounds == 0:
            st.failures += 1
            self._back_off(ctx)

    def _back_off(self, ctx: Context) -> None:
        """Algorithm 2: pick one of the freest directions and a distance, then re-plan."""
        st = self.state
        candidates = backoff_candidates(st.cell, st.obstacles, self.dims, self.profile)
        options = backoff_options(st.cell, candidates, self.inflated_static, self.dims, self.profile)
        if not options:
            # Nowhere valid to go: plan again to the current target instead.
            self._stop(flush=True)
            if st.targets:
                self._request_path(ctx, st.targets[-1])
            return
        choice = ctx.choose(options)
        self._report_status(ctx, "backing_off")
        self._set_target(ctx, choice.target)

    # -- helpers ----------------------------------------------------------------

    def _set_target(self, ctx: Context, target: Cell) -> None:
        st = self.state
        self._stop(flush=True)
        rows, cols = self.shape
        target = clamp_target(target, rows, cols, self.margin)
        if not st.targets or st.targets[-1] != target:
            st.targets = (*st.targets, target)
        self._request_path(ctx, target)

    def _request_path(self, ctx: Context, target: Cell) -> None:
        final = len(self.state.targets) <= 1
        ctx.call("/generate_path", PathRequest(self.name, self.state.cell, target, final), self.on_path)
        self._report_status(ctx, "planning")

    def _stop(self, flush: bool) -> None:
        st = self.state
        st.velocity = 0
        if flush:
            st.moves, st.move_idx = (), 0
        st.waits, st.waiting = 0, False

    def _report_pose(self, ctx: Context) -> None:
        st = self.state
        ctx.publish("/poses", RobotPose(self.name, st.cell, st.dir, st.velocity, st.done))

    def _report_status(self, ctx: Context, mode: str) -> None:
        st = self.state
        ctx.publish("status", RobotStatus(self.name, mode, st.cell, self.final_goal(),
                                          st.waits, st.failures, ctx.now()))
