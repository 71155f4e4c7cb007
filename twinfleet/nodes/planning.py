"""Path planning of the map server (docs/robots.md §3).

The planning grid is the inflated static map plus the other robots (cell, gap
rule, look-ahead), with the requester's neighbours freed. The model's A*
(``rebeca``) expands 7 neighbours (no SE), scans its open list in insertion
order and never improves a discovered cell; the ``fixed`` A* is the standard
8-neighbour search with a binary heap and decrease-key (lazy deletion).
Step costs are 1 and SQRT2 = 1.4142 in both; diagonal steps between two
blocked orthogonal cells are allowed in both (no corner-cutting rule: the
inflation by one cell already keeps paths off obstacle corners).
"""

from __future__ import annotations

import heapq
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from twinfleet.nodes.grid import NB, SQRT2, Cell, Dims, direction_between, octile
from twinfleet.nodes.memo import CellsMemo
from twinfleet.nodes.profile import Profile
from twinfleet.runtime.contract.node import PureMemo

#: The model's "infinite" g/f.
INF = 9999.0


@dataclass(frozen=True, slots=True)
class OtherRobot:
    """Another robot as the map server knows it (last report).

    Attributes:
        cell: its cell; outside the map (e.g. (−1, −1)) means not yet known.
        dir: its heading 0..7.
        velocity_cells: last reported speed in cells/s (0 = standing).
    """

    cell: Cell
    dir: int
    velocity_cells: float


@dataclass(frozen=True, slots=True)
class SearchResult:
    """Outcome of one A* search.

    Attributes:
        path: cells from start to goal inclusive, or None on failure.
        expanded: number of cells popped (closed).
        max_open: largest size of the open list.
    """

    path: list[Cell] | None
    expanded: int
    max_open: int


def _mark(grid: np.ndarray, x: int, y: int) -> None:
    if 0 <= x < grid.shape[0] and 0 <= y < grid.shape[1]:
        grid[x, y] = True


def planning_grid(
    static_inflated: np.ndarray,
    omap: np.ndarray,
    others: Sequence[OtherRobot],
    requester_cell: Cell,
    dims: Dims,
    profile: Profile,
) -> np.ndarray:
    """Grid for one path request (docs/robots.md §3).

    Args:
        static_inflated: static occupancy dilated once by the profile's rule (precomputed by
            the caller, `mapfile.static_grids`).
        omap: un-inflated static occupancy.
        others: every robot except the requester.
        requester_cell: the start of the request; its in-map neighbours that are
            statically free are freed again.
        dims: fleet dimensions (res, width, safe margin).
        profile: rounding rule.

    Returns:
        A new bool grid (True = blocked).
    """
    grid = static_inflated.copy()
    rows, cols = grid.shape
    min_gap = profile.round((dims.width + 2 * dims.safe_margin) / dims.res)
    for o in others:
        rx, ry = o.cell
        if not (0 <= rx < rows and 0 <= ry < cols):
            continue  # not reported yet
        grid[rx, ry] = True
        # Gap rule: a robot too close to a border closes the gap behind it.
        # The far side uses `size − r` (not `size − 1 − r`), as in the model.
        if ry < min_gap:
            grid[rx, :ry] = True
        elif cols - ry < min_gap:
            grid[rx, ry + 1 :] = True
        if rx < min_gap:
            grid[:rx, ry] = True
        elif rows - rx < min_gap:
            grid[rx + 1 :, ry] = True
        if o.velocity_cells != 0:
            ahead = max(2, profile.round(0.2 * o.velocity_cells))
            dx, dy = NB[o.dir % 8]
            for k in range(1, ahead + 1):
                _mark(grid, rx + k * dx, ry + k * dy)
    sx, sy = requester_cell
    for dx, dy in NB:
        nx, ny = sx + dx, sy + dy
        if 0 <= nx < rows and 0 <= ny < cols and not omap[nx, ny]:
            grid[nx, ny] = False
    return grid


def _walk_back(parent: dict[Cell, Cell], goal: Cell) -> list[Cell]:
    path = [goal]
    while path[-1] in parent:
        path.append(parent[path[-1]])
    path.reverse()
    return path


def _astar_model(grid: np.ndarray, start: Cell, goal: Cell) -> SearchResult:
    """The model's A*: 7 neighbours, insertion-ordered open list, first discovery
    (docs/robots.md §3)."""
    rows, cols = grid.shape
    blocked = grid.tolist()  # nested lists index faster than numpy scalars
    g: dict[Cell, float] = {start: 0.0}
    f: dict[Cell, float] = {start: 0.0 + octile(start, goal)}
    parent: dict[Cell, Cell] = {}
    closed: set[Cell] = set()
    open_list = [start]
    max_open, expanded = 1, 0
    steps = [(NB[k][0], NB[k][1], SQRT2 if k % 2 else 1.0) for k in range(7)]
    while True:
        best, best_f = -1, INF
        for i, c in enumerate(open_list):
            if f[c] < best_f:  # strict: the earliest inserted wins ties
                best, best_f = i, f[c]
        if best < 0:
            return SearchResult(None, expanded, max_open)
        cur = open_list.pop(best)
        closed.add(cur)
        expanded += 1
        if cur == goal:
            return SearchResult(_walk_back(parent, goal), expanded, max_open)
        cx, cy = cur
        gc = g[cur]
        for dx, dy, cost in steps:
            nx, ny = cx + dx, cy + dy
            n = (nx, ny)
            if not (0 <= nx < rows and 0 <= ny < cols) or blocked[nx][ny] or n in g:
                continue
            gn = gc + cost
            g[n] = gn
            f[n] = gn + octile(n, goal)
            parent[n] = cur
            open_list.append(n)
        max_open = max(max_open, len(open_list))


def _astar_standard(grid: np.ndarray, start: Cell, goal: Cell) -> SearchResult:
    """Standard 8-neighbour A* with a heap; ties broken by (f, h, insertion order)."""
    rows, cols = grid.shape
    blocked = grid.tolist()
    g: dict[Cell, float] = {start: 0.0}
    parent: dict[Cell, Cell] = {}
    closed: set[Cell] = set()
    h0 = octile(start, goal)
    heap: list[tuple[float, float, int, Cell]] = [(h0, h0, 0, start)]
    counter, expanded, max_open = 1, 0, 1
    steps = [(dx, dy, SQRT2 if k % 2 else 1.0) for k, (dx, dy) in enumerate(NB)]
    while heap:
        _, _, _, cur = heapq.heappop(heap)
        if cur in closed:
            continue  # stale entry superseded by a decrease-key
        closed.add(cur)
        expanded += 1
        if cur == goal:
            return SearchResult(_walk_back(parent, goal), expanded, max_open)
        cx, cy = cur
        gc = g[cur]
        for dx, dy, cost in steps:
            nx, ny = cx + dx, cy + dy
            n = (nx, ny)
            if not (0 <= nx < rows and 0 <= ny < cols) or blocked[nx][ny] or n in closed:
                continue
            gn = gc + cost
            if gn < g.get(n, INF * 1e6):
                g[n] = gn
                parent[n] = cur
                h = octile(n, goal)
                heapq.heappush(heap, (gn + h, h, counter, n))
                counter += 1
        max_open = max(max_open, len(heap))
    return SearchResult(None, expanded, max_open)


def astar(grid: np.ndarray, start: Cell, goal: Cell, profile: Profile) -> SearchResult:
    """Run the profile's A* on a planning grid.

    The start cell is never tested; the goal must be free (it is found on pop).

    Args:
        grid: bool grid, True = blocked.
        start: start cell (inside the grid).
        goal: goal cell.
        profile: ``planner_neighbours``/``planner_relax`` select the variant.

    Returns:
        The search result (path None on failure or goal outside the grid).
    """
    rows, cols = grid.shape
    if not (0 <= start[0] < rows and 0 <= start[1] < cols):
        return SearchResult(None, 0, 0)
    if profile.planner_neighbours == 7 and not profile.planner_relax:
        return _astar_model(grid, start, goal)
    if profile.planner_neighbours == 8 and profile.planner_relax:
        return _astar_standard(grid, start, goal)
    raise ValueError(
        "unsupported planner combination: neighbours="
        f"{profile.planner_neighbours}, relax={profile.planner_relax}"
    )


def generate_path(grid: np.ndarray, start: Cell, goal: Cell, profile: Profile) -> list[Cell] | None:
    """Raw A* path from ``start`` to ``goal`` inclusive, or None."""
    return astar(grid, start, goal, profile).path


def remove_zigzags(path: Sequence[Cell]) -> list[Cell]:
    """The model's zig-zag removal (docs/robots.md §3); the start is never output.

    With P[1..n] the raw path, P[i] is dropped when 3 ≤ i ≤ n−1, P[i−1] was not
    dropped, and P[i] is one orthogonal step from both P[i−1] and P[i+1].
    """
    n = len(path)
    out: list[Cell] = []
    last_dropped = -1  # 1-based index
    for i in range(2, n + 1):
        p = path[i - 1]
        if 3 <= i <= n - 1 and last_dropped != i - 1:
            a, b = path[i - 2], path[i]
            if (
                abs(p[0] - a[0]) + abs(p[1] - a[1]) == 1
                and abs(p[0] - b[0]) + abs(p[1] - b[1]) == 1
            ):
                last_dropped = i
                continue
        out.append(p)
    return out


def _pure(a: Cell, b: Cell) -> bool:
    dx, dy = b[0] - a[0], b[1] - a[1]
    return (dx, dy) != (0, 0) and (dx == 0 or dy == 0 or abs(dx) == abs(dy))


def consolidate_waypoints(start: Cell, waypoints: Sequence[Cell]) -> list[Cell]:
    """Collapse straight runs of waypoints to their end point (docs/robots.md §3).

    A waypoint is replaced by the next one when both legs (from the previous
    kept point, and onwards) are straight 8-way segments in the same
    direction, so the sign-direction walk (docs/robots.md §3) still lands on every
    remaining waypoint. Directions are taken from the previous *kept* point
    (the C++ code takes them from the last raw point).
    """
    out: list[Cell] = []
    for w in waypoints:
        if out:
            before = out[-2] if len(out) > 1 else start
            last = out[-1]
            if (
                _pure(before, last)
                and _pure(last, w)
                and direction_between(before, last) == direction_between(last, w)
            ):
                out[-1] = w
                continue
        out.append(w)
    return out


def plan_waypoints(
    grid: np.ndarray, start: Cell, goal: Cell, profile: Profile, consolidate: bool = False
) -> list[Cell]:
    """Waypoints for a request: A*, zig-zag removal, optional consolidation.

    Returns:
        The waypoints (start excluded); empty on failure and when start == goal
        (docs/robots.md §3).
    """
    path = generate_path(grid, start, goal, profile)
    if not path:
        return []
    wps = remove_zigzags(path)
    return consolidate_waypoints(start, wps) if consolidate else wps


class PathPlanner(PureMemo):  # its content grows, its answers do not change
    """Memoised planning on one static map: `plan` is a pure function of its arguments.

    The checker asks for the same plan (same start, goal and robot positions)
    again and again on different interleavings; the memo answers those at once.
    """

    def __init__(self, static_inflated: np.ndarray, omap: np.ndarray, dims: Dims,
                 profile: Profile, maxsize: int = 65536) -> None:
        self.static_inflated, self.omap, self.dims, self.profile = static_inflated, omap, dims, profile
        self._memo = CellsMemo(maxsize)

    def plan(self, others: Sequence[OtherRobot], start: Cell, goal: Cell) -> tuple[Cell, ...]:
        """Waypoints from `start` (excluded) to `goal` around `others`; () when none."""
        return self._memo.get((tuple(others), start, goal), lambda: self._plan(others, start, goal))

    def _plan(self, others: Sequence[OtherRobot], start: Cell, goal: Cell) -> tuple[Cell, ...]:
        grid = planning_grid(self.static_inflated, self.omap, others, start, self.dims, self.profile)
        return tuple(plan_waypoints(grid, start, goal, self.profile))
