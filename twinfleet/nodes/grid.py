"""Grid geometry shared by planning, scan, collision and motion (docs/robots.md §2).

Cells are ``(x, y)`` = (PGM row, PGM column). Directions 0..7 run
counter-clockwise from +x in 45° steps; odd directions are diagonal. The
"model frame" in metres has its axes along +x (rows) and +y (columns), origin
at the corner of cell (0, 0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

Cell = tuple[int, int]

#: Neighbour offsets by direction: E, NE, N, NW, W, SW, S, SE.
NB: tuple[Cell, ...] = ((1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1))

#: The model's and the C++ code's sqrt(2) (not math.sqrt(2)).
SQRT2 = 1.4142
#: The model's 8-entry cos/sin tables for robot-frame rotations (±0.7071).
COS8: tuple[float, ...] = (1.0, 0.7071, 0.0, -0.7071, -1.0, -0.7071, 0.0, 0.7071)
SIN8: tuple[float, ...] = (0.0, 0.7071, 1.0, 0.7071, 0.0, -0.7071, -1.0, -0.7071)

_DIR_OF_SIGN: dict[Cell, int] = {off: d for d, off in enumerate(NB)}


def _sign(v: int) -> int:
    return (v > 0) - (v < 0)


def is_diagonal(d: int) -> bool:
    """True for the diagonal directions (odd numbers)."""
    return d % 2 == 1


def direction_between(a: Cell, b: Cell) -> int:
    """Sign direction from ``a`` towards ``b`` (8-way, docs/robots.md §3).

    Raises:
        ValueError: ``a == b`` (no direction).
    """
    s = (_sign(b[0] - a[0]), _sign(b[1] - a[1]))
    if s == (0, 0):
        raise ValueError(f"no direction from a cell to itself: {a}")
    return _DIR_OF_SIGN[s]


def step(cell: Cell, d: int, n: int = 1) -> Cell:
    """The cell ``n`` steps from ``cell`` in direction ``d``."""
    dx, dy = NB[d]
    return (cell[0] + n * dx, cell[1] + n * dy)


def octile(a: Cell, b: Cell) -> float:
    """Octile distance in cells with the model's SQRT2: (SQRT2−1)·min + max."""
    dx, dy = abs(a[0] - b[0]), abs(a[1] - b[1])
    return (SQRT2 - 1) * min(dx, dy) + max(dx, dy)


def chebyshev(a: Cell, b: Cell) -> int:
    """Chebyshev (king-move) distance in cells."""
    return max(abs(a[0] - b[0]), abs(a[1] - b[1]))


def in_bounds(cell: Cell, shape: tuple[int, int]) -> bool:
    """True if ``cell`` lies inside a grid of ``shape`` = (rows, cols)."""
    return 0 <= cell[0] < shape[0] and 0 <= cell[1] < shape[1]


def cell_centre(cell: Cell, res: float) -> tuple[float, float]:
    """Model-frame centre of a cell in metres: ((x+0.5)·R, (y+0.5)·R)."""
    return ((cell[0] + 0.5) * res, (cell[1] + 0.5) * res)


def world_to_cell(
    x: float, y: float, res: float, origin: tuple[float, float] = (0.0, 0.0)
) -> Cell:
    """Model-frame metres to a cell: floor((p − origin)/R), the paper's conversion
    (docs/robots.md §2)."""
    return (math.floor((x - origin[0]) / res), math.floor((y - origin[1]) / res))


def cell_to_world(
    cell: Cell, res: float, origin: tuple[float, float] = (0.0, 0.0)
) -> tuple[float, float]:
    """Cell to model-frame metres (its centre), the inverse of :func:`world_to_cell`."""
    cx, cy = cell_centre(cell, res)
    return (origin[0] + cx, origin[1] + cy)


def heading_to_dir(theta_deg: float, nearest: bool = False) -> int:
    """Heading in degrees (model frame, 0 = +x, CCW) to a direction 0..7.

    Args:
        theta_deg: heading in degrees, any range.
        nearest: False = the paper's floor(θ/45); True = the nearest direction.
    """
    q = theta_deg / 45.0
    return (round(q) if nearest else math.floor(q)) % 8


def dir_to_heading(d: int) -> float:
    """Direction to heading in degrees: 45·d."""
    return 45.0 * (d % 8)


def inflate(occ: np.ndarray, cells: int = 1) -> np.ndarray:
    """8-neighbour dilation, ``cells`` times, no wrap-around at the borders (docs/robots.md §3).

    Args:
        occ: bool grid (rows, cols).
        cells: number of dilations (0 returns a copy).

    Returns:
        A new bool grid.
    """
    out = np.asarray(occ, dtype=bool).copy()
    for _ in range(cells):
        src = out.copy()
        # Shift-or in both axes: a separable 3x3 max filter.
        out[1:, :] |= src[:-1, :]
        out[:-1, :] |= src[1:, :]
        src = out.copy()
        out[:, 1:] |= src[:, :-1]
        out[:, :-1] |= src[:, 1:]
    return out


def inflate_one_pass(occ: np.ndarray) -> np.ndarray:
    """The model's ``expandObstacles``: one dilation written in place, row by row.

    The model copies each cell into the output when its row-major scan reaches
    it, so a mark that an obstacle visited *earlier* made on that cell is
    overwritten again; only marks from obstacles visited later survive. A free
    cell (i, j) therefore ends up blocked iff one of (i, j+1), (i+1, j−1),
    (i+1, j), (i+1, j+1) is occupied: obstacles grow towards lower rows and
    columns only (REBECA's initial plans of r1 and r5 depend on it, docs/robots.md §3).

    Args:
        occ: bool grid (rows, cols).

    Returns:
        A new bool grid.
    """
    src = np.asarray(occ, dtype=bool)
    out = src.copy()
    out[:, :-1] |= src[:, 1:]  # (i, j+1)
    out[:-1, 1:] |= src[1:, :-1]  # (i+1, j-1)
    out[:-1, :] |= src[1:, :]  # (i+1, j)
    out[:-1, :-1] |= src[1:, 1:]  # (i+1, j+1)
    return out


@dataclass(frozen=True, slots=True)
class Dims:
    """Physical constants of a fleet (defaults: docs/robots.md §8).

    Attributes:
        res: cell size R in metres.
        length: robot length L (m).
        width: robot width W (m).
        safe_margin: lateral safety margin (m).
        stop_zone: extra stopping distance (m).
        collision_margin: margin added to each half size in the shadow test (m).
    """

    res: float = 0.255
    length: float = 0.4
    width: float = 0.4
    safe_margin: float = 0.02
    stop_zone: float = 0.3
    collision_margin: float = 0.02

    def __post_init__(self) -> None:
        for name in ("res", "length", "width"):
            if not getattr(self, name) > 0:
                raise ValueError(f"Dims.{name} must be positive, got {getattr(self, name)}")

    def steplen(self, d: int) -> float:
        """Length of one hop in direction ``d``: R, or SQRT2·R for diagonals."""
        return SQRT2 * self.res if is_diagonal(d) else self.res
