from __future__ import annotations

import math
import time

import numpy as np
import pytest

from twinfleet.nodes.grid import NB, Dims
from twinfleet.nodes.profile import FIXED, REBECA
from twinfleet.nodes.scan import (
    EXACT_STEP,
    Scanner,
    build_tables,
    can_hop,
    frontal_clearance,
    scan_cells,
    stepwise_free,
    stop_threshold,
)


def brute_model_scan(occ, cell, d, others):
    """Scalar re-statement of the model's scan (docs/robots.md §4), beam by beam."""
    rows, cols = occ.shape
    grid = occ.copy()
    for ox, oy in others:
        if 0 <= ox < rows and 0 <= oy < cols:
            grid[ox, oy] = True
    out = []
    for k in range(92):
        a = (45 * d - 91 + 2 * k) % 360
        c, s = round(math.cos(math.radians(a)), 4), round(math.sin(math.radians(a)), 4)
        dist = 0.8
        while dist < 40:
            x, y = math.trunc(cell[0] + dist * c), math.trunc(cell[1] + dist * s)
            if not (0 <= x < rows and 0 <= y < cols):
                break
            if grid[x, y]:
                if not out or out[-1] != (x, y):
                    out.append((x, y))
                break
            dist += 0.8
    return tuple(out)


def brute_exact_scan(occ, cell, d, others, tables):
    rows, cols = occ.shape
    grid = occ.copy()
    for ox, oy in others:
        if 0 <= ox < rows and 0 <= oy < cols:
            grid[ox, oy] = True
    out = []
    for b in range(tables.beams):
        a = math.radians(45 * d - 90 + 2 * b)
        for k in range(1, 1000):
            dist = k * EXACT_STEP
            if dist >= 10.0 / 0.255:
                break
            x = math.floor(cell[0] + 0.5 + dist * math.cos(a))
            y = math.floor(cell[1] + 0.5 + dist * math.sin(a))
            if not (0 <= x < rows and 0 <= y < cols):
                break
            if grid[x, y]:
                if (x, y) not in out:
                    out.append((x, y))
                break
    return tuple(out)


def test_model_tables_shape():
    t = build_tables(REBECA)
    assert t.beams == 92
    assert t.beam_angles[0, 0] == 360 - 91
    assert t.beam_angles[0, -1] == 91
    assert t.dx.shape[2] == 50  # 0.8 accumulated stays below 40 for the 50th sample


def test_exact_tables_shape():
    t = build_tables(FIXED)
    assert t.beams == 91
    assert t.beam_angles[2, 0] == 0
    assert t.beam_angles[2, -1] == 180


def test_model_scan_matches_brute_force(occ50):
    t = build_tables(REBECA)
    rng = np.random.default_rng(7)
    cells = [(-1, -1), (0, 0), (49, 49), (5, 5)]
    cells += [tuple(int(v) for v in rng.integers(0, 50, 2)) for _ in range(60)]
    for i, cell in enumerate(cells):
        d = i % 8
        others = [tuple(int(v) for v in rng.integers(-1, 50, 2)) for _ in range(4)]
        assert scan_cells(occ50, cell, d, others, t) == brute_model_scan(occ50, cell, d, others)


def test_model_scan_matches_brute_force_random_maps():
    t = build_tables(REBECA)
    rng = np.random.default_rng(11)
    for k in range(40):
        occ = rng.random((int(rng.integers(5, 60)), int(rng.integers(5, 60)))) < 0.08
        cell = (int(rng.integers(0, occ.shape[0])), int(rng.integers(0, occ.shape[1])))
        assert scan_cells(occ, cell, k % 8, [], t) == brute_model_scan(occ, cell, k % 8, [])


def test_exact_scan_matches_brute_force_random_maps():
    t = build_tables(FIXED)
    rng = np.random.default_rng(12)
    for k in range(25):
        occ = rng.random((int(rng.integers(5, 50)), int(rng.integers(5, 50)))) < 0.08
        cell = (int(rng.integers(0, occ.shape[0])), int(rng.integers(0, occ.shape[1])))
        others = [(cell[0] + 2, cell[1])]
        got = scan_cells(occ, cell, k % 8, others, t)
        assert got == brute_exact_scan(occ, cell, k % 8, others, t)


def test_scan_sees_other_robot_and_not_behind():
    occ = np.zeros((20, 20), dtype=bool)
    t = build_tables(REBECA)
    assert scan_cells(occ, (10, 10), 0, [(14, 10)], t) == ((14, 10),)
    assert scan_cells(occ, (10, 10), 0, [(6, 10)], t) == ()  # behind the robot
    assert scan_cells(occ, (10, 10), 0, [(30, 30)], t) == ()  # off the map: ignored
    # off the map beside a row whose cell id (x * cols + y) it would share: ignored too
    assert scan_cells(occ, (10, 10), 0, [(13, 30), (15, -10)], t) == ()


def test_scanner_keeps_beams_per_cell_and_heading_and_scans_as_scan_cells(occ50):
    # A scan starts from its cell and heading's beams, kept (two of every three scans here
    # reuse them): the same hits as scanning afresh, robots on and off the map alike.
    t = build_tables(REBECA)
    sc = Scanner(occ50, t, beams=8)
    rng = np.random.default_rng(5)
    cells = [tuple(int(v) for v in rng.integers(0, 50, 2)) for _ in range(12)]
    for k in range(150):
        cell, d = cells[k % 12], k % 3
        others = [tuple(int(v) for v in rng.integers(-3, 53, 2)) for _ in range(4)]
        assert sc.scan(cell, d, others) == scan_cells(occ50, cell, d, others, t)
    assert len(sc._beams) == 8  # least recently used evicted


def test_scanner_memo_is_pure(occ50):
    t = build_tables(REBECA)
    sc = Scanner(occ50, t, maxsize=4)
    a = sc.scan((5, 5), 2, [(5, 15), (5, 25)])
    assert sc.scan((5, 5), 2, [(5, 25), (5, 15)]) == a
    for i in range(10):
        sc.scan((i, i), 0, [])
    assert sc.scan((5, 5), 2, [(5, 15), (5, 25)]) == scan_cells(occ50, (5, 5), 2, [(5, 15), (5, 25)], t)


def test_scan_speed(occ50):
    t = build_tables(REBECA)
    n = 300
    t0 = time.perf_counter()
    for i in range(n):
        scan_cells(occ50, (5 + i % 40, 5 + (3 * i) % 40), i % 8, [(20, 20), (30, 30)], t)
    assert (time.perf_counter() - t0) / n < 1e-3


def _blocking(cell, d, dims):
    out = set()
    for dx in range(-4, 5):
        for dy in range(-4, 5):
            if (dx, dy) != (0, 0) and not can_hop(cell, d, [(cell[0] + dx, cell[1] + dy)], dims):
                out.add((dx, dy))
    return out


def test_blocking_offsets_east_and_northeast():
    dims = Dims()
    assert _blocking((20, 20), 0, dims) == {(1, 0), (2, 0)}
    assert _blocking((20, 20), 1, dims) == {(1, 0), (0, 1), (1, 1), (2, 1), (1, 2), (2, 2)}


@pytest.mark.parametrize("d", range(8))
def test_blocking_offsets_rotate(d):
    got = _blocking((20, 20), d, Dims())
    base = {(1, 0), (2, 0)} if d % 2 == 0 else {(1, 0), (0, 1), (1, 1), (2, 1), (1, 2), (2, 2)}
    # rotate by (d // 2) quarter turns: (x, y) -> (-y, x)
    for _ in range(d // 2):
        base = {(-y, x) for x, y in base}
    assert got == base


def test_stop_thresholds():
    assert stop_threshold(0, Dims()) == pytest.approx(0.755)
    assert stop_threshold(1, Dims()) == pytest.approx(0.8606, abs=1e-4)


def test_clearance_none_and_lateral_band():
    assert frontal_clearance((5, 5), 0, [], 0.255, 0.4, 0.02) == 9999.0
    assert frontal_clearance((5, 5), 0, [(7, 6)], 0.255, 0.4, 0.02) == 9999.0  # lateral 0.255
    assert frontal_clearance((5, 5), 0, [(3, 5)], 0.255, 0.4, 0.02) == 9999.0  # behind
    assert frontal_clearance((5, 5), 0, [(9, 5), (7, 5)], 0.255, 0.4, 0.02) == pytest.approx(0.51)
    assert stepwise_free((5, 5), 0, [], 0.255, 0.4, 0.02) == 9999


def test_stepwise_float_quirks():
    # The model's floating point (docs/robots.md §4): from (5, 5) one cell E or NE gives 0, W or SW 1.
    want = {0: 0, 1: 0, 4: 1, 5: 1}
    for d, n in want.items():
        ob = [(5 + NB[d][0], 5 + NB[d][1])]
        assert stepwise_free((5, 5), d, ob, 0.255, 0.4, 0.02) == n


def test_tables_are_built_once_per_configuration_and_read_only():
    # every map server instance asks for them (a check makes three of each node)
    tables = build_tables(REBECA, 180.0, 10.0, 2.0, 0.255)
    assert build_tables(REBECA, 180.0, 10.0, 2.0, 0.255) is tables
    assert build_tables(REBECA, 180.0, 5.0, 2.0, 0.255) is not tables
    assert not any(a.flags.writeable for a in (tables.dx, tables.dy, tables.beam_angles))
