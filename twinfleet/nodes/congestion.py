"""Congestion resolution: the back-off of Algorithm 2 as the model does it (docs/robots.md §6).

These functions only enumerate the options; the robot picks one through
``ctx.choose`` so that the checker branches over all of them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from twinfleet.nodes.grid import NB, Cell, Dims
from twinfleet.nodes.profile import Profile
from twinfleet.nodes.scan import NO_OBSTACLE, stepwise_free

#: Back-off lengths offered by the model's ``?(4, 6, 8, 10, 12)``.
BACKOFF_STEPS: tuple[int, ...] = (4, 6, 8, 10, 12)
#: Number of freest directions offered (``?(0, 1, 2, 3)``).
BACKOFF_RANKS = 4
#: 9999 ("nothing seen") stored through the model's xy2idx decodes as 999.
UNSEEN_FREE = 999


@dataclass(frozen=True, slots=True)
class BackoffOption:
    """One back-off alternative.

    Attributes:
        dir: direction 0..7.
        steps: cells to move, already capped by the free space.
        target: the back-off cell (after clamping to the border band).
    """

    dir: int
    steps: int
    target: Cell


def selection_sort_desc(records: Sequence[tuple[int, int]]) -> list[tuple[int, int]]:
    """The model's unstable selection sort by the second field, descending.

    For each position p, the first record among p.. with the strictly largest
    key is swapped into p.
    """
    out = list(records)
    for p in range(len(out)):
        best = p
        for q in range(p + 1, len(out)):
            if out[q][1] > out[best][1]:
                best = q
        out[p], out[best] = out[best], out[p]
    return out


def backoff_candidates(
    robot_cell: Cell, obstacles: Sequence[Cell], dims: Dims, profile: Profile
) -> tuple[tuple[int, int], ...]:
    """The 4 freest directions with their free hop counts (``maxback``), best first.

    Args:
        robot_cell: the robot's cell.
        obstacles: the robot's last scan (absolute cells).
        dims: fleet dimensions.
        profile: unused today (both profiles rank alike); kept for symmetry.

    Returns:
        ((dir, maxback), ...) of length 4; unseen directions count 999.
    """
    del profile
    recs = []
    for d in range(8):
        free = stepwise_free(robot_cell, d, obstacles, dims.res, dims.width, dims.safe_margin)
        recs.append((d, UNSEEN_FREE if free == int(NO_OBSTACLE) else free))
    return tuple(selection_sort_desc(recs)[:BACKOFF_RANKS])


def clamp_target(cell: Cell, rows: int, cols: int, margin: int = 1) -> Cell:
    """Clamp a target into [margin, size−1−margin] per axis, as the model's ``setTarget``
    does (docs/robots.md §6)."""
    return (
        min(max(cell[0], margin), rows - 1 - margin),
        min(max(cell[1], margin), cols - 1 - margin),
    )


def target_margin(dims: Dims, profile: Profile) -> int:
    """Border band of ``setTarget``: round(SAFE_MARGIN/R) (1 with round_m)."""
    return profile.round(dims.safe_margin / dims.res)


def backoff_target(
    robot_cell: Cell, d: int, steps: int, maxback: int, rows: int, cols: int, margin: int = 1
) -> Cell:
    """Back-off cell: robot + min(steps, maxback)·NB[d], clamped to the border band."""
    n = min(steps, maxback)
    dx, dy = NB[d]
    return clamp_target((robot_cell[0] + n * dx, robot_cell[1] + n * dy), rows, cols, margin)


def target_valid(robot_cell: Cell, target: Cell, raw: Cell, static_inflated: np.ndarray) -> bool:
    """A back-off target worth planning to: on the map, not in an inflated obstacle, not here."""
    rows, cols = static_inflated.shape
    if not (0 <= raw[0] < rows and 0 <= raw[1] < cols):
        return False
    return target != robot_cell and not static_inflated[target]


def backoff_options(
    robot_cell: Cell,
    candidates: Sequence[tuple[int, int]],
    static_inflated: np.ndarray,
    dims: Dims,
    profile: Profile,
) -> tuple[BackoffOption, ...]:
    """Every (direction rank, steps) alternative, rank-major then steps.

    ``rebeca``: all 4 × 5 alternatives, repeats included (they are distinct
    transitions in the model). With ``validate_backoff``: drop targets that are
    off the map (before clamping), inside the inflated static map, or the
    robot's own cell (a zero-step back-off always fails to plan), and
    drop repeated targets. The result may then be empty.
    """
    rows, cols = static_inflated.shape
    margin = target_margin(dims, profile)
    out: list[BackoffOption] = []
    seen: set[Cell] = set()
    for d, maxback in candidates:
        for steps in BACKOFF_STEPS:
            n = min(steps, maxback)
            raw = (robot_cell[0] + n * NB[d][0], robot_cell[1] + n * NB[d][1])
            target = clamp_target(raw, rows, cols, margin)
            if profile.validate_backoff:
                if target in seen or not target_valid(robot_cell, target, raw, static_inflated):
                    continue
                seen.add(target)
            out.append(BackoffOption(d, n, target))
    return tuple(out)
