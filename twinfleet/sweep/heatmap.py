"""A heatmap of two swept parameters, drawn with Pillow: one cell per pair of values,
coloured by verdict, with labelled axes and a legend.

When the sweep has more axes than the two drawn, a cell stands for every point with its
pair of values and shows the worst verdict among them (error over violated over unknown
over holds): a green cell holds at every value of the other axes.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from PIL import Image, ImageDraw, ImageFont

from twinfleet.sweep.grid import Axis, format_value
from twinfleet.sweep.point import PointResult

#: verdict → cell colour (RGB); also the legend's order
COLOURS: dict[str, tuple[int, int, int]] = {
    "holds": (46, 160, 67),
    "violated": (214, 39, 40),
    "unknown": (160, 160, 160),
    "contract breach": (148, 103, 189),
    "error": (255, 150, 30),
}
_WORST = ("error", "contract breach", "violated", "unknown", "holds")
CELL = 56  # pixels per cell side
_LEFT, _TOP, _BOTTOM = 120, 50, 110
_BACKGROUND, _INK = (255, 255, 255), (20, 20, 20)


class HeatmapError(ValueError):
    """`--heatmap X,Y` names no swept parameter, or the same one twice."""


def pick_axes(axes: Sequence[Axis], spec: str) -> tuple[Axis, Axis]:
    """The two axes ``X,Y`` names.

    Raises:
        HeatmapError: not two names of swept parameters.
    """
    names = [n.strip() for n in spec.split(",")]
    by_name = {a.name: a for a in axes}
    if len(names) != 2 or names[0] == names[1]:
        raise HeatmapError(f"--heatmap {spec!r}: expected two different parameters X,Y")
    for name in names:
        if name not in by_name:
            raise HeatmapError(f"--heatmap {spec!r}: {name!r} is not swept (swept: "
                               f"{', '.join(by_name)})")
    return by_name[names[0]], by_name[names[1]]


def cell_verdicts(x: Axis, y: Axis, results: Sequence[PointResult]) -> dict[tuple[int, int],
                                                                             str]:
    """(column, row) → the worst verdict of the points with those two values."""
    cells: dict[tuple[int, int], str] = {}
    for r in results:
        values = dict(r.point)
        where = (x.values.index(values[x.name]), y.values.index(values[y.name]))
        old = cells.get(where, "holds")
        cells[where] = min(old, r.verdict, key=lambda v: _WORST.index(v) if v in _WORST else 0)
    return cells


def cell_centre(x: Axis, y: Axis, column: int, row: int) -> tuple[int, int]:
    """The pixel at the centre of a cell; row 0 (the first Y value) is at the bottom."""
    return (_LEFT + column * CELL + CELL // 2,
            _TOP + (len(y.values) - 1 - row) * CELL + CELL // 2)


def draw(x: Axis, y: Axis, results: Sequence[PointResult], title: str,
         path: str | Path) -> Path:
    """Write the heatmap PNG to `path` and return it."""
    font = _font()
    width = max(_LEFT + len(x.values) * CELL + 30, 460)
    height = _TOP + len(y.values) * CELL + _BOTTOM
    image = Image.new("RGB", (width, height), _BACKGROUND)
    pen = ImageDraw.Draw(image)
    pen.text((10, 12), title, fill=_INK, font=font)
    for (column, row), verdict in cell_verdicts(x, y, results).items():
        cx, cy = cell_centre(x, y, column, row)
        half = CELL // 2
        pen.rectangle((cx - half, cy - half, cx + half - 2, cy + half - 2),
                      fill=COLOURS.get(verdict, COLOURS["error"]))
    bottom = _TOP + len(y.values) * CELL
    for column, value in enumerate(x.values):
        cx = cell_centre(x, y, column, 0)[0]
        _centred(pen, (cx, bottom + 6), format_value(value), font)
    for row, value in enumerate(y.values):
        cy = cell_centre(x, y, 0, row)[1]
        _right(pen, (_LEFT - 8, cy), format_value(value), font)
    _centred(pen, (_LEFT + len(x.values) * CELL // 2, bottom + 28), x.name, font)
    pen.text((10, _TOP - 20), y.name, fill=_INK, font=font)
    _legend(pen, font, {r.verdict for r in results}, bottom + 60)
    image.save(path)
    return Path(path)


Font = ImageFont.FreeTypeFont | ImageFont.ImageFont


def _font() -> Font:
    """Pillow's own font at 14 px; its small bitmap font before Pillow 10.1 (no sizes)."""
    try:
        return ImageFont.load_default(size=14)
    except TypeError:
        return ImageFont.load_default()


# Text is placed from its measured box rather than with Pillow's `anchor`, which bitmap
# fonts do not take.
def _centred(pen: ImageDraw.ImageDraw, top_middle: tuple[int, int], text: str,
             font: Font) -> None:
    left, _, right, _ = pen.textbbox((0, 0), text, font=font)
    pen.text((top_middle[0] - (right - left) // 2, top_middle[1]), text, fill=_INK, font=font)


def _right(pen: ImageDraw.ImageDraw, right_middle: tuple[int, int], text: str,
           font: Font) -> None:
    left, top, right, bottom = pen.textbbox((0, 0), text, font=font)
    pen.text((right_middle[0] - (right - left), right_middle[1] - (bottom + top) // 2), text,
             fill=_INK, font=font)


def _legend(pen: ImageDraw.ImageDraw, font: Font,
            seen: set[str], top: int) -> None:
    left = 10
    for verdict, colour in COLOURS.items():
        if verdict not in seen and verdict not in ("holds", "violated", "unknown"):
            continue
        pen.rectangle((left, top, left + 16, top + 16), fill=colour)
        pen.text((left + 22, top + 1), verdict, fill=_INK, font=font)
        left += 34 + int(pen.textlength(verdict, font=font))
