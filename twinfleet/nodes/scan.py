"""Laser scan and the robot's use of it (docs/robots.md §4).

A scan returns the *cells* of the first obstacle hit by each beam. The model
mode reproduces the Timed Rebeca model exactly (corner origin, 92 beams at
±91°, 0.8-cell steps accumulated in floating point, cos/sin rounded to 4
decimals, trunc to cells); the exact mode samples from the cell centre over
-fov/2..+fov/2 with exact trigonometry and a finer step.
"""

from __future__ import annotations

import functools
import math
from collections import OrderedDict
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from twinfleet.nodes.grid import COS8, SIN8, Cell, Dims, cell_centre
from twinfleet.nodes.memo import CellsMemo
from twinfleet.nodes.profile import Profile
from twinfleet.runtime.contract.node import PureMemo

#: Sample step along a beam, in cells, per scan mode.
MODEL_STEP = 0.8
EXACT_STEP = 0.25
#: "Nothing ahead" value of the clearance functions (metres or steps).
NO_OBSTACLE = 9999.0


@dataclass(frozen=True, eq=False)
class ScanTables:
    """Per-heading beam sample offsets, built once per configuration.

    Attributes:
        mode: ``"model"`` or ``"exact"``.
        origin_offset: added to the robot cell to get the beam origin (0 or 0.5).
        dx, dy: float arrays (8, beams, samples): offsets in cells, by heading.
        beam_angles: int/float array (8, beams): absolute beam angle in degrees.
    """

    mode: str
    origin_offset: float
    dx: np.ndarray = field(repr=False)
    dy: np.ndarray = field(repr=False)
    beam_angles: np.ndarray = field(repr=False)

    @property
    def beams(self) -> int:
        """Number of beams per scan."""
        return int(self.dx.shape[1])


def _model_trig(angle_deg: int) -> tuple[float, float]:
    # The model reads cos and sin from a table rounded to 4 decimals (docs/robots.md §4).
    rad = math.radians(angle_deg % 360)
    return round(math.cos(rad), 4), round(math.sin(rad), 4)


# Kept per arguments: every node instance of a map server builds them (a check validates
# a scenario's nodes, lints and searches with instances of their own: three), a few ms
# each, and they are read-only.
@functools.lru_cache(maxsize=4)
def build_tables(
    profile: Profile,
    fov_deg: float = 180.0,
    max_range_m: float = 10.0,
    angle_inc_deg: float = 2.0,
    res: float = 0.255,
) -> ScanTables:
    """Precompute the beam geometry for every heading.

    Args:
        profile: selects the model or the exact scan.
        fov_deg: field of view.
        max_range_m: maximum range in metres.
        angle_inc_deg: beam spacing.
        res: cell size (to express the range in cells).

    Returns:
        The tables.
    """
    max_cells: float
    if profile.scan_mode == "model":
        max_cells = profile.round(max_range_m / res)  # 40 with round_m
        half = profile.round(fov_deg / 2)  # 91
        beams = profile.round(abs(2 * half) / angle_inc_deg)  # 92
        ds, d = [], MODEL_STEP
        while d < max_cells:  # accumulated like the model's loop
            ds.append(d)
            d += MODEL_STEP
        rel = [-half + k * angle_inc_deg for k in range(beams)]
        origin = 0.0
    else:
        max_cells = max_range_m / res
        beams = int(math.floor(fov_deg / angle_inc_deg + 1e-9)) + 1
        n = int(math.ceil(max_cells / EXACT_STEP))
        ds = [k * EXACT_STEP for k in range(1, n) if k * EXACT_STEP < max_cells]
        rel = [-fov_deg / 2 + k * angle_inc_deg for k in range(beams)]
        origin = 0.5
    dist = np.array(ds)
    dx = np.empty((8, len(rel), len(ds)))
    dy = np.empty_like(dx)
    angles = np.empty((8, len(rel)))
    for h in range(8):
        for b, r in enumerate(rel):
            a = 45 * h + r
            if profile.scan_mode == "model":
                a = int(round(a)) % 360
                c, s = _model_trig(a)
            else:
                a = a % 360.0
                c, s = math.cos(math.radians(a)), math.sin(math.radians(a))
            angles[h, b] = a
            dx[h, b] = dist * c
            dy[h, b] = dist * s
    for arr in (dx, dy, angles):
        arr.setflags(write=False)
    return ScanTables(profile.scan_mode, origin, dx, dy, angles)


def scan_cells(
    static_occ: np.ndarray,
    robot_cell: Cell,
    robot_dir: int,
    other_cells: Iterable[Cell],
    tables: ScanTables,
) -> tuple[Cell, ...]:
    """Cells of the first obstacle on each beam, in beam order.

    Args:
        static_occ: un-inflated occupancy (rows, cols).
        robot_cell: the scanning robot's cell (may be (−1, −1) before it reports).
        robot_dir: its heading 0..7.
        other_cells: other robots' cells (those outside the map are ignored).
        tables: from :func:`build_tables`.

    Returns:
        Hit cells; the model mode drops a hit equal to the previous one, the
        exact mode drops every repeat.
    """
    return beam_hits(Beams.of(static_occ, robot_cell, robot_dir, tables), other_cells)


@dataclass(frozen=True, eq=False)
class Beams:
    """The samples of one scan's beams as the static map sees them, whatever the other
    robots do (a `Scanner` keeps them per robot cell and heading).

    Attributes:
        mode: the tables' scan mode.
        rows, cols: the map's size (a sample's cell is ``divmod(id, cols)``).
        ids: (beams, samples) cell ids ``x * cols + y`` of the samples, -1 outside the
            map; only the samples up to the last beam's first static stop are kept.
        static: (beams, samples) True where a sample hits a static obstacle.
        blocked: ``static`` or outside the map: where a beam stops without robots.
    """

    mode: str
    rows: int
    cols: int
    ids: np.ndarray = field(repr=False)
    static: np.ndarray = field(repr=False)
    blocked: np.ndarray = field(repr=False)

    @staticmethod
    def of(static_occ: np.ndarray, robot_cell: Cell, robot_dir: int,
           tables: ScanTables) -> Beams:
        """The beams of a robot at `robot_cell` heading `robot_dir` on `static_occ`."""
        rows, cols = static_occ.shape
        h = robot_dir % 8
        if tables.mode == "model":
            # trunc of (integer + offset) in floating point, exactly as the model (the cast
            # to integers truncates).
            xi = (robot_cell[0] + tables.dx[h]).astype(np.int64)
            yi = (robot_cell[1] + tables.dy[h]).astype(np.int64)
        else:
            xi = np.floor(robot_cell[0] + 0.5 + tables.dx[h]).astype(np.int64)
            yi = np.floor(robot_cell[1] + 0.5 + tables.dy[h]).astype(np.int64)
        inside = (xi >= 0) & (xi < rows) & (yi >= 0) & (yi < cols)
        ids = np.where(inside, xi * cols + yi, -1)
        # a sample outside the map (-1) reads the map's last cell, which `inside` masks
        static = static_occ.ravel()[ids] & inside
        blocked = static | ~inside
        # Past every beam's first stop no sample can be a first hit: kept small per heading.
        stops = np.where(blocked.any(axis=1), blocked.argmax(axis=1), blocked.shape[1] - 1)
        end = int(stops.max()) + 1
        kind = np.int16 if rows * cols < 1 << 15 else np.int64
        return Beams(tables.mode, rows, cols, ids[:, :end].astype(kind), static[:, :end],
                     blocked[:, :end])


def beam_hits(beams: Beams, other_cells: Iterable[Cell]) -> tuple[Cell, ...]:
    """`scan_cells` of `beams` with the other robots at `other_cells` (module docstring)."""
    ids, rows, cols = beams.ids, beams.rows, beams.cols
    hit = beams.static
    for ox, oy in other_cells:
        if 0 <= ox < rows and 0 <= oy < cols:
            hit = hit | (ids == ox * cols + oy)
    first = (hit | beams.blocked).argmax(axis=1)
    lanes = np.arange(hit.shape[0])
    found = ids[lanes, first][hit[lanes, first]].tolist()  # cell ids: one id, one cell
    if beams.mode == "model":  # a cell again right after itself counts once
        out, last = [], -1
        for i in found:
            if i != last:
                out.append(divmod(i, cols))
                last = i
        return tuple(out)
    return tuple(divmod(i, cols) for i in dict.fromkeys(found))  # each cell once


class Scanner(PureMemo):  # its content grows, its answers do not change
    """Memoised :func:`scan_cells` for one static map (a pure function of its inputs).

    A scan that is not memoised yet starts from the beams of its robot's cell and heading
    (`Beams`, kept too): what the static map does to them is the same for any other
    robots, and most of a scan's work (a model check of C1a scans 3-4 times per cell and
    heading).

    Args:
        static_occ: un-inflated occupancy; copied and frozen.
        tables: beam tables.
        maxsize: number of memo entries kept (least recently used evicted).
        beams: number of (cell, heading) `Beams` kept (least recently used evicted; each
            a few kB to ~20 kB).
    """

    def __init__(self, static_occ: np.ndarray, tables: ScanTables, maxsize: int = 65536,
                 beams: int = 1024) -> None:
        self._occ = np.array(static_occ, dtype=bool)
        self._occ.setflags(write=False)
        self.tables = tables
        self._memo = CellsMemo(maxsize)
        self._beams: OrderedDict[tuple[Cell, int], Beams] = OrderedDict()
        self._beams_kept = beams

    def scan(self, robot_cell: Cell, robot_dir: int, other_cells: Iterable[Cell]) -> tuple[Cell, ...]:
        """Scan from ``robot_cell`` heading ``robot_dir`` with the other robots at ``other_cells``."""
        others = tuple(sorted(set(other_cells)))  # order and repeats do not matter
        return self._memo.get((robot_cell, robot_dir % 8, others), lambda: beam_hits(
            self._beams_of(robot_cell, robot_dir % 8), others))

    def _beams_of(self, robot_cell: Cell, heading: int) -> Beams:
        kept, key = self._beams, (robot_cell, heading)
        found = kept.get(key)
        if found is not None:
            kept.move_to_end(key)
            return found
        found = kept[key] = Beams.of(self._occ, robot_cell, heading, self.tables)
        if len(kept) > self._beams_kept:
            kept.popitem(last=False)
        return found


def frontal_clearance(
    robot_cell: Cell,
    d: int,
    obstacle_cells: Sequence[Cell],
    res: float,
    robot_width: float,
    safe_margin: float,
) -> float:
    """Distance (m) to the nearest obstacle centre ahead in direction ``d`` (docs/robots.md §4).

    Obstacles count when forward > 0 and |lateral| ≤ max(W/2, steplen/2) + margin.
    The arithmetic follows the model's operation order so that its floating
    point quirks reproduce.

    Returns:
        The smallest forward distance, or 9999.0 if none.
    """
    steplen = 1.4142 * res if d % 2 else res
    ymax = max(robot_width / 2 + safe_margin, steplen / 2 + safe_margin)
    c, s = COS8[d], SIN8[d]
    px, py = cell_centre(robot_cell, res)
    best = NO_OBSTACLE
    for ox, oy in obstacle_cells:
        dx = (ox + 0.5) * res - px
        dy = (oy + 0.5) * res - py
        f = dx * c + dy * s
        if f > 0 and abs(-dx * s + dy * c) <= ymax and f < best:
            best = f
    return best


def stepwise_free(
    robot_cell: Cell,
    d: int,
    obstacle_cells: Sequence[Cell],
    res: float,
    robot_width: float,
    safe_margin: float,
) -> int:
    """Free hops before the nearest obstacle in ``d``: trunc(f/steplen), 9999 if none
    (docs/robots.md §4)."""
    f = frontal_clearance(robot_cell, d, obstacle_cells, res, robot_width, safe_margin)
    if f == NO_OBSTACLE:
        return int(NO_OBSTACLE)
    steplen = 1.4142 * res if d % 2 else res
    return math.trunc(f / steplen)


def stop_threshold(d: int, dims: Dims) -> float:
    """Minimum clearance for a hop: steplen + L/2 + STOP_ZONE (0.755 m edge, 0.8606 m diagonal)."""
    return dims.steplen(d) + dims.length / 2 + dims.stop_zone


def can_hop(robot_cell: Cell, d: int, obstacles: Sequence[Cell], dims: Dims,
            robots: Sequence[Cell] = ()) -> bool:
    """True if the robot may hop one cell in direction ``d`` (the stop check, docs/robots.md §4).

    ``obstacles`` are point-sized (the model's ±(W/2 + margin) band); ``robots``
    are cells known to hold another robot, tested with a band one robot width
    wider, because their body reaches into the neighbouring lane.
    """
    f = frontal_clearance(robot_cell, d, obstacles, dims.res, dims.width, dims.safe_margin)
    if robots:
        wide = 2 * dims.width + 2 * dims.safe_margin  # band W + 2·margin either side
        f = min(f, frontal_clearance(robot_cell, d, robots, dims.res, wide, dims.safe_margin))
    return f > stop_threshold(d, dims)
