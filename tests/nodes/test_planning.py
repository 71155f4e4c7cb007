from __future__ import annotations

import heapq

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from twinfleet.nodes.grid import NB, SQRT2, Dims, direction_between, inflate
from twinfleet.nodes.planning import (
    OtherRobot,
    astar,
    consolidate_waypoints,
    generate_path,
    plan_waypoints,
    planning_grid,
    remove_zigzags,
)
from twinfleet.nodes.profile import FIXED, REBECA

#: The initial plans RMC computes on the model (its robots' `moves` after the first
#: `onNewPath` at t = 0; docs/robots.md §3): waypoints, start excluded.
RMC_PLANS = {
    "r1": ((5, 5), (45, 45), "6,6 7,7 8,8 9,9 10,10 11,11 12,12 13,13 14,14 15,15 16,16 18,16 "
           "20,16 22,16 24,16 25,16 26,17 27,18 28,19 29,20 30,21 30,23 30,25 30,27 31,28 32,29 "
           "33,30 34,31 35,32 36,33 37,34 38,35 39,36 40,37 41,38 42,39 42,41 42,42 43,43 44,44 "
           "45,45"),
    "r2": ((5, 15), (45, 35), "6,15 8,15 10,15 12,15 14,15 16,15 18,15 20,15 22,15 24,15 25,15 "
           "26,16 27,17 28,18 29,19 30,20 31,21 32,22 33,23 34,24 35,25 36,26 37,27 38,28 39,29 "
           "40,30 41,31 42,32 43,33 44,34 45,35"),
    "r3": ((5, 25), (45, 25), "6,25 8,25 10,25 12,25 14,25 16,25 18,25 20,25 22,25 24,25 26,25 "
           "28,25 30,25 32,25 34,25 35,25 36,26 37,27 38,28 40,28 42,28 43,27 44,26 45,25"),
    "r4": ((5, 35), (45, 15), "6,35 8,35 10,35 12,35 14,35 16,35 18,35 20,35 22,35 24,35 26,35 "
           "27,34 28,33 28,31 30,31 31,30 32,29 33,28 34,27 35,26 35,24 35,22 36,21 37,20 38,19 "
           "40,19 42,19 43,18 44,17 45,16 45,15"),
    "r5": ((5, 45), (45, 5), "6,45 7,44 8,43 9,42 10,41 11,40 12,39 13,38 14,37 15,36 16,35 "
           "17,34 18,33 19,32 20,31 21,30 22,29 23,28 24,27 25,26 26,25 27,24 28,23 29,22 30,21 "
           "31,20 32,19 33,18 34,17 35,16 36,15 37,14 38,13 39,12 40,11 41,10 42,9 43,8 44,7 "
           "45,6 45,5"),
}


def cells(text):
    return [tuple(int(v) for v in c.split(",")) for c in text.split()]


def initial_plan(occ50, inflated50, start, goal):
    grid = planning_grid(inflated50, occ50, [], start, Dims(), REBECA)
    res = astar(grid, start, goal, REBECA)
    return res, remove_zigzags(res.path)


@pytest.mark.parametrize("robot", sorted(RMC_PLANS))
def test_initial_plans_are_rmcs(occ50, inflated50, robot):
    start, goal, plan = RMC_PLANS[robot]
    _, wps = initial_plan(occ50, inflated50, start, goal)
    assert wps == cells(plan)


def test_full_inflation_gives_other_plans_for_r1_and_r5(occ50):
    # An ordinary 8-neighbour dilation plans r1 and r5 differently from the model, whose
    # expandObstacles keeps only the marks towards lower rows and columns (docs/robots.md §3).
    full = inflate(occ50)
    for robot in RMC_PLANS:
        start, goal, plan = RMC_PLANS[robot]
        _, wps = initial_plan(occ50, full, start, goal)
        assert (wps == cells(plan)) == (robot in ("r2", "r3", "r4")), robot


def test_model_astar_never_steps_se(occ50, inflated50):
    res, _ = initial_plan(occ50, inflated50, (5, 45), (45, 5))
    steps = {(b[0] - a[0], b[1] - a[1]) for a, b in zip(res.path, res.path[1:], strict=False)}
    assert (1, -1) not in steps


def dijkstra_cost(grid, start, goal):
    rows, cols = grid.shape
    dist = {start: 0.0}
    pq = [(0.0, start)]
    while pq:
        d, c = heapq.heappop(pq)
        if c == goal:
            return d
        if d > dist[c]:
            continue
        for k, (dx, dy) in enumerate(NB):
            n = (c[0] + dx, c[1] + dy)
            if 0 <= n[0] < rows and 0 <= n[1] < cols and not grid[n]:
                nd = d + (SQRT2 if k % 2 else 1.0)
                if nd < dist.get(n, float("inf")):
                    dist[n] = nd
                    heapq.heappush(pq, (nd, n))
    return None


def path_cost(path):
    return sum(SQRT2 if a[0] != b[0] and a[1] != b[1] else 1.0 for a, b in zip(path, path[1:], strict=False))


@settings(max_examples=150, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    rows=st.integers(1, 14),
    cols=st.integers(1, 14),
    density=st.floats(0.0, 0.45),
)
def test_fixed_astar_is_optimal(seed, rows, cols, density):
    rng = np.random.default_rng(seed)
    grid = rng.random((rows, cols)) < density
    start = (int(rng.integers(rows)), int(rng.integers(cols)))
    goal = (int(rng.integers(rows)), int(rng.integers(cols)))
    grid[start] = False
    want = dijkstra_cost(grid, start, goal)
    path = generate_path(grid, start, goal, FIXED)
    if want is None:
        assert path is None
        return
    assert path is not None
    assert path[0] == start
    assert path[-1] == goal
    for a, b in zip(path, path[1:], strict=False):
        assert max(abs(a[0] - b[0]), abs(a[1] - b[1])) == 1
        assert not grid[b]
    assert path_cost(path) == pytest.approx(want, abs=1e-9)


def test_fixed_astar_deterministic(occ50, inflated50):
    a = generate_path(inflated50, (5, 45), (45, 5), FIXED)
    assert a == generate_path(inflated50, (5, 45), (45, 5), FIXED)
    assert path_cost(a) == pytest.approx(dijkstra_cost(inflated50, (5, 45), (45, 5)))


def test_astar_goal_blocked_or_start_outside(inflated50):
    assert generate_path(inflated50, (5, 5), (20, 20), REBECA) is None
    assert generate_path(inflated50, (5, 5), (20, 20), FIXED) is None
    assert generate_path(inflated50, (-1, -1), (5, 5), REBECA) is None


def test_plan_waypoints_start_equals_goal_fails(inflated50):
    for p in (REBECA, FIXED):
        assert plan_waypoints(inflated50, (5, 5), (5, 5), p) == []
        assert plan_waypoints(inflated50, (5, 5), (20, 20), p) == []
        assert plan_waypoints(inflated50, (5, 5), (6, 6), p) == [(6, 6)]


def test_remove_zigzags_rules():
    assert remove_zigzags([(0, 0)]) == []
    assert remove_zigzags([(0, 0), (1, 0)]) == [(1, 0)]
    # straight run: every second interior point dropped, never two in a row
    run = [(i, 0) for i in range(6)]
    assert remove_zigzags(run) == [(1, 0), (3, 0), (5, 0)]
    # staircase becomes diagonals
    stair = [(0, 0), (1, 0), (1, 1), (2, 1), (2, 2)]
    assert remove_zigzags(stair) == [(1, 0), (2, 1), (2, 2)]
    # the last point is never dropped
    assert remove_zigzags([(0, 0), (1, 0), (2, 0)]) == [(1, 0), (2, 0)]


def test_zigzag_gaps_walkable(occ50, inflated50):
    """Every gap is one diagonal or two straight cells, so the sign walk lands on waypoints."""
    for start, goal in [((5, 5), (45, 45)), ((5, 45), (45, 5)), ((5, 35), (45, 15))]:
        _, wps = initial_plan(occ50, inflated50, start, goal)
        prev = start
        for w in wps:
            dx, dy = w[0] - prev[0], w[1] - prev[1]
            assert (abs(dx), abs(dy)) in {(1, 0), (0, 1), (1, 1), (2, 0), (0, 2)}
            prev = w


def test_consolidate_waypoints():
    start = (0, 0)
    wps = [(1, 0), (3, 0), (5, 0), (6, 1), (7, 2), (7, 4)]
    assert consolidate_waypoints(start, wps) == [(5, 0), (7, 2), (7, 4)]
    assert consolidate_waypoints(start, []) == []


def test_consolidated_plan_walks_same_cells(occ50, inflated50):
    def walk(start, wps):
        cur, seen = start, []
        for w in wps:
            while cur != w:
                d = direction_between(cur, w)
                cur = (cur[0] + NB[d][0], cur[1] + NB[d][1])
                seen.append(cur)
        return seen

    grid = planning_grid(inflated50, occ50, [], (5, 5), Dims(), REBECA)
    raw = plan_waypoints(grid, (5, 5), (45, 45), REBECA)
    cons = plan_waypoints(grid, (5, 5), (45, 45), REBECA, consolidate=True)
    assert len(cons) < len(raw)
    assert walk((5, 5), cons) == walk((5, 5), raw)


def test_planning_grid_other_robot_lookahead_and_unblock(occ50, inflated50):
    dims = Dims()
    other = OtherRobot((10, 30), 0, 2)
    g = planning_grid(inflated50, occ50, [other], (5, 5), dims, REBECA)
    assert g[10, 30]
    assert g[11, 30]
    assert g[12, 30]
    assert not g[13, 30]
    still = planning_grid(inflated50, occ50, [OtherRobot((10, 30), 0, 0)], (5, 5), dims, REBECA)
    assert still[10, 30]
    assert not still[11, 30]
    # requester next to the other robot: its neighbours are freed, its own cell not tested
    g2 = planning_grid(inflated50, occ50, [other], (10, 31), dims, REBECA)
    assert not g2[10, 30]
    assert not g2[11, 30]
    assert g2[12, 30]
    # statically occupied neighbours stay blocked; inflation-only ones are freed
    g3 = planning_grid(inflated50, occ50, [], (9, 17), dims, REBECA)
    assert g3[9, 18]
    assert not g3[8, 17]


def test_planning_grid_unknown_robot_ignored(occ50, inflated50):
    g = planning_grid(inflated50, occ50, [OtherRobot((-1, -1), 0, 3)], (5, 5), Dims(), REBECA)
    assert (g == planning_grid(inflated50, occ50, [], (5, 5), Dims(), REBECA)).all()


def test_planning_grid_gap_rule():
    occ = np.zeros((50, 50), dtype=bool)
    inf = inflate(occ)
    dims = Dims()
    g = planning_grid(inf, occ, [OtherRobot((20, 1), 2, 0)], (40, 40), dims, REBECA)
    assert g[20, 0]
    assert g[20, 1]
    assert not g[20, 2]
    g = planning_grid(inf, occ, [OtherRobot((20, 48), 2, 0)], (40, 40), dims, REBECA)
    assert not g[20, 49]  # far side only triggers at 49 (50 − 48 = 2 is not < 2)
    g = planning_grid(inf, occ, [OtherRobot((49, 20), 2, 0)], (10, 10), dims, REBECA)
    assert g[49, 20]
    assert not g[48, 20]
    g = planning_grid(inf, occ, [OtherRobot((1, 20), 2, 0)], (40, 40), dims, REBECA)
    assert g[0, 20]
    g = planning_grid(inf, occ, [OtherRobot((20, 49), 6, 0)], (40, 40), dims, REBECA)
    assert g[20, 49]
    assert not g[20, 48]
