"""Collision ("shadow") tests between two robots (docs/robots.md §7).

``corner_box`` is the model's test: an axis-aligned box spanned by two rotated
corners, and a strict corner-inside-box check (misses many real overlaps).
``sat`` is the exact overlap test of two oriented rectangles by the separating
axis theorem.
"""

from __future__ import annotations

import math

from twinfleet.nodes.grid import COS8, SIN8, Cell, Dims, cell_centre
from twinfleet.nodes.profile import Profile

Box = tuple[float, float, float, float]  # (xmin, ymin, xmax, ymax)


def shadow_box(cell: Cell, d: int, res: float, half_len: float, half_wid: float) -> Box:
    """The model's shadow: bounding box of the corners (+a, +b) and (−a, −b) rotated by ``d``.

    Args:
        cell: robot cell.
        d: heading 0..7 (8-entry ±0.7071 tables).
        res: cell size.
        half_len: a = L/2 + margin.
        half_wid: b = W/2 + margin.

    Returns:
        (xmin, ymin, xmax, ymax) in model-frame metres; degenerate (a segment)
        for diagonal headings when a == b.
    """
    cx, cy = cell_centre(cell, res)
    c, s = COS8[d], SIN8[d]
    p1 = (cx + (half_len * c - half_wid * s), cy + (half_len * s + half_wid * c))
    p2 = (cx + (-half_len * c + half_wid * s), cy + (-half_len * s - half_wid * c))
    return (min(p1[0], p2[0]), min(p1[1], p2[1]), max(p1[0], p2[0]), max(p1[1], p2[1]))


def _corner_strictly_inside(box: Box, other: Box) -> bool:
    xmin, ymin, xmax, ymax = other
    return any(
        xmin < px < xmax and ymin < py < ymax
        for px in (box[0], box[2])
        for py in (box[1], box[3])
    )


def boxes_hit(a: Box, b: Box) -> bool:
    """The model's test: a corner of one box strictly inside the other, either way."""
    return _corner_strictly_inside(a, b) or _corner_strictly_inside(b, a)


def _axes(heading_rad: float) -> tuple[tuple[float, float], tuple[float, float]]:
    c, s = math.cos(heading_rad), math.sin(heading_rad)
    return (c, s), (-s, c)


def rects_overlap(
    ca: tuple[float, float],
    heading_a: float,
    cb: tuple[float, float],
    heading_b: float,
    half_len: float,
    half_wid: float,
) -> bool:
    """Exact overlap of two equal oriented rectangles (separating axis theorem).

    Args:
        ca, cb: centres (m).
        heading_a, heading_b: headings in radians (length axis).
        half_len, half_wid: half sizes.

    Returns:
        True if the interiors intersect (touching edges do not count).
    """
    ua, va = _axes(heading_a)
    ub, vb = _axes(heading_b)
    tx, ty = cb[0] - ca[0], cb[1] - ca[1]
    for ax, ay in (ua, va, ub, vb):
        dist = abs(tx * ax + ty * ay)
        ra = half_len * abs(ua[0] * ax + ua[1] * ay) + half_wid * abs(va[0] * ax + va[1] * ay)
        rb = half_len * abs(ub[0] * ax + ub[1] * ay) + half_wid * abs(vb[0] * ax + vb[1] * ay)
        if dist >= ra + rb:
            return False
    return True


def shadows_intersect(
    a_cell: Cell, a_dir: int, b_cell: Cell, b_dir: int, dims: Dims, profile: Profile
) -> bool:
    """Collision between two robots by the profile's test.

    Half sizes are L/2 + COLLISION_MARGIN and W/2 + COLLISION_MARGIN.

    Args:
        a_cell, a_dir: pose of robot a.
        b_cell, b_dir: pose of robot b.
        dims: fleet dimensions.
        profile: ``corner_box`` (model) or ``sat`` (exact).
    """
    a = dims.length / 2 + dims.collision_margin
    b = dims.width / 2 + dims.collision_margin
    if profile.collision == "corner_box":
        return boxes_hit(
            shadow_box(a_cell, a_dir, dims.res, a, b), shadow_box(b_cell, b_dir, dims.res, a, b)
        )
    return rects_overlap(
        cell_centre(a_cell, dims.res),
        math.radians(45 * a_dir),
        cell_centre(b_cell, dims.res),
        math.radians(45 * b_dir),
        a,
        b,
    )
