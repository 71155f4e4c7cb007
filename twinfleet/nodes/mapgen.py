"""Deterministic map generators and the built-in maps of ``maps/``.

``random_map`` draws rectangles and elliptic blobs like the paper's map
(free border, a handful of obstacles) from ``numpy.random.default_rng(seed)``:
an offline, seeded generator, not node behaviour. Run
``python -m nodes.mapgen [DIR]`` to regenerate the built-in maps.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from twinfleet.nodes.mapfile import save_map

FREE = 255
OCCUPIED = 0

#: Built-in generated maps: name → (resolution, seed or None for hand-made).
RANDOM100_SEED = 2024
BUILTIN_RES = 0.255


def random_map(
    rows: int,
    cols: int,
    seed: int,
    obstacles: int = 6,
    min_size: int = 4,
    max_size: int = 14,
    border: int = 3,
) -> np.ndarray:
    """A seeded random map of rectangles and blobs with a free border.

    Args:
        rows, cols: grid size.
        seed: RNG seed; equal arguments give equal maps.
        obstacles: number of shapes.
        min_size, max_size: extent range of a shape in cells.
        border: width of the obstacle-free band along the edges.

    Returns:
        uint8 gray image: 0 = obstacle, 255 = free.
    """
    if rows <= 2 * border + min_size or cols <= 2 * border + min_size:
        raise ValueError(f"map {rows}x{cols} too small for border {border} and size {min_size}")
    rng = np.random.default_rng(seed)
    img = np.full((rows, cols), FREE, dtype=np.uint8)
    xs, ys = np.mgrid[0:rows, 0:cols]
    for k in range(obstacles):
        h = int(rng.integers(min_size, max_size + 1))
        w = int(rng.integers(min_size, max_size + 1))
        h, w = min(h, rows - 2 * border), min(w, cols - 2 * border)
        x0 = int(rng.integers(border, rows - border - h + 1))
        y0 = int(rng.integers(border, cols - border - w + 1))
        if k % 2 == 0:
            img[x0 : x0 + h, y0 : y0 + w] = OCCUPIED
        else:
            cx, cy = x0 + (h - 1) / 2, y0 + (w - 1) / 2
            blob = ((xs - cx) / (h / 2)) ** 2 + ((ys - cy) / (w / 2)) ** 2 <= 1.0
            img[blob] = OCCUPIED
    return img


def corridor_map() -> np.ndarray:
    """12×12 corridor for a head-on meeting.

    Walls fill rows 0–3 and 8–11 over columns 3–8; the corridor is rows 4–7
    (4 cells physically, so after the one-cell inflation two planning lanes,
    rows 5 and 6, stay open). Columns 0–2 and 9–11 are open bays where robots
    can back off.
    """
    img = np.full((12, 12), FREE, dtype=np.uint8)
    img[0:4, 3:9] = OCCUPIED
    img[8:12, 3:9] = OCCUPIED
    return img


def lanes_map(lanes: int, length: int, width: int = 3, wall: int = 1) -> np.ndarray:
    """``lanes`` parallel corridors that never meet: one per robot, walls between them.

    Lane ``k`` holds rows ``wall + k·(width + wall)`` .. ``+ width − 1`` and runs
    along the columns (+y, the direction robots face at start); walls of
    ``wall`` rows separate the lanes and enclose the map, and columns 0 and
    ``length − 1`` close the lanes' ends, so no planner path, scan beam or
    robot shadow crosses from one lane into another.

    Args:
        lanes: number of corridors (>= 1).
        length: columns of the map, end walls included (>= 5).
        width: free rows per lane; 3 leaves one planning row after the one-cell
            inflation, with the side walls outside a robot's stop band.
        wall: rows of wall between and around lanes (>= 1).

    Returns:
        uint8 gray image: 0 = obstacle, 255 = free.
    """
    if lanes < 1 or length < 5 or width < 1 or wall < 1:
        raise ValueError(f"lanes_map needs lanes >= 1, length >= 5, width >= 1, wall >= 1; "
                         f"got {lanes}, {length}, {width}, {wall}")
    rows = wall + lanes * (width + wall)
    img = np.full((rows, length), OCCUPIED, dtype=np.uint8)
    for k in range(lanes):
        top = lane_row(k, width, wall) - width // 2
        img[top : top + width, 1 : length - 1] = FREE
    return img


def lane_row(lane: int, width: int = 3, wall: int = 1) -> int:
    """The middle row of lane ``lane`` in :func:`lanes_map` (where its robot drives)."""
    return wall + lane * (width + wall) + width // 2


def write_builtin_maps(directory: str | Path) -> list[Path]:
    """Write ``corridor12`` and ``random100`` (PGM + YAML) into ``directory``.

    Returns:
        The YAML paths written.
    """
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    maps = {
        "corridor12": (corridor_map(), "twinfleet corridor12"),
        "random100": (
            random_map(100, 100, RANDOM100_SEED, obstacles=16, max_size=18),
            f"twinfleet random_map(100, 100, seed={RANDOM100_SEED}, obstacles=16, max_size=18)",
        ),
    }
    out = []
    for name, (img, comment) in maps.items():
        rows, cols = img.shape
        origin = (-rows * BUILTIN_RES / 2, -cols * BUILTIN_RES / 2, 0.0)
        yaml_path = d / f"{name}.yaml"
        save_map(yaml_path, img, BUILTIN_RES, origin, comment)
        out.append(yaml_path)
    return out


if __name__ == "__main__":
    for p in write_builtin_maps(sys.argv[1] if len(sys.argv) > 1 else "maps"):
        print(p)
