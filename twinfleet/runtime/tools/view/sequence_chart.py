"""A message-sequence chart of any counterexample: lifelines, messages, state changes.

Input is the plain JSON form of a walked trace (`twinfleet trace show --json`:
nodes, steps with what each handled and sent, changed states, the violated
property), so any system can be drawn, with or without a map. `layout` turns
it into drawing primitives — one lifeline per node, one row per step with a
box on the node that ran, an arrow from the step that sent a message to the
step that handled it, the fields that changed and the faults injected (a
message dropped or duplicated, a node crashed) beside the box, the violated
property at the foot in red — and `to_svg` / `to_png` paint the same
primitives, so the two files always show the same chart.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from html import escape
from pathlib import Path
from typing import Any, Final, final

from PIL import Image, ImageDraw

BLACK: Final = (0, 0, 0)
GREY: Final = (150, 150, 150)
BLUE: Final = (30, 90, 200)
RED: Final = (220, 0, 0)
WHITE: Final = (255, 255, 255)
BOX_FILL: Final = (235, 242, 255)

COLUMN_PX: Final = 190  # between two lifelines
ROW_PX: Final = 34  # between two steps
TOP_PX: Final = 40  # the node names above the first step
LEFT_PX: Final = 70  # the time column
NOTE_PX: Final = 320  # room right of the last lifeline for state changes
LABEL_CHARS: Final = 34  # of a message's label on its arrow


@final
@dataclass(frozen=True, slots=True)
class Line:
    """A straight line; `arrow` puts a head at its end."""

    x1: float
    y1: float
    x2: float
    y2: float
    colour: tuple[int, int, int]
    width: int = 1
    arrow: bool = False


@final
@dataclass(frozen=True, slots=True)
class Box:
    """A filled rectangle with an outline."""

    x1: float
    y1: float
    x2: float
    y2: float
    fill: tuple[int, int, int]
    outline: tuple[int, int, int]


@final
@dataclass(frozen=True, slots=True)
class Text:
    """One line of text, its top-left corner at (x, y)."""

    x: float
    y: float
    text: str
    colour: tuple[int, int, int] = BLACK


Shape = Line | Box | Text


@final
@dataclass(frozen=True, slots=True)
class Chart:
    """A chart's size and what it is made of."""

    width: int
    height: int
    shapes: tuple[Shape, ...]
    lifelines: tuple[str, ...]


def layout(walk: Mapping[str, Any]) -> Chart:
    """The chart of a walked trace (module docstring)."""
    nodes = list(walk["nodes"])
    x = {n: LEFT_PX + COLUMN_PX * (i + 0.5) for i, n in enumerate(nodes)}
    steps = list(walk["steps"])
    height = TOP_PX + ROW_PX * (len(steps) + 2) + 20
    width = int(LEFT_PX + COLUMN_PX * len(nodes) + NOTE_PX)
    shapes: list[Shape] = []
    for n in nodes:
        shapes.append(Text(x[n] - 4 * len(n), 10, n))
        shapes.append(Line(x[n], TOP_PX - 8, x[n], height - 40, GREY))
    waiting: list[tuple[float, Mapping[str, Any], str]] = []  # (row y, sent event, sender)
    last = len(steps) - 1
    for k, step in enumerate(steps):
        y = TOP_PX + ROW_PX * (k + 1)
        shapes += _step_shapes(step, y, x, waiting, violating=k == last)
        waiting += [(y, s, step["node"]) for s in step["sent"] if s["target"] != step["node"]]
    foot = TOP_PX + ROW_PX * (len(steps) + 1) + 6
    shapes.append(Text(8, foot, f"violated: {walk['property']}: {walk['message']}", RED))
    return Chart(width, height, tuple(shapes), tuple(nodes))


def _step_shapes(step: Mapping[str, Any], y: float, x: Mapping[str, float],
                 waiting: list[tuple[float, Mapping[str, Any], str]], *,
                 violating: bool) -> list[Shape]:
    node = step["node"]
    colour = RED if violating or step.get("failure") else BLUE
    out: list[Shape] = [Text(6, y - 6, f"t={step['time']}", GREY),
                        Box(x[node] - 7, y - 9, x[node] + 7, y + 9, BOX_FILL, colour),
                        Text(x[node] + 10, y - 16, f"{step['index']}. {step['handler']}", colour)]
    sent = _match(step, waiting)
    if sent is not None:
        y0, _, sender = sent
        label = f"{step['name'] or step['kind']}: {step['args']}"
        out.append(Line(x[sender], y0, x[node] + (-8 if x[sender] < x[node] else 8), y, BLACK,
                        arrow=True))
        mid = (x[sender] + x[node]) / 2
        out.append(Text(mid - 3 * min(len(label), LABEL_CHARS), (y0 + y) / 2 - 14,
                        _cut(label), BLACK))
    note = "; ".join(f"{n}: {_fields(d)}" for n, d in step.get("changed", {}).items())
    if step.get("failure"):
        note = f"FAILED {step['failure']}" + (f"; {note}" if note else "")
    faults = "; ".join(f"FAULT {f}" for f in step.get("faults") or ())
    if faults:  # first: a dropped message is why an arrow never comes
        note = faults + (f"; {note}" if note else "")
    if note:
        right = max(x.values()) + COLUMN_PX / 2
        out.append(Text(right, y - 6, _cut(note, 60), RED if violating else BLACK))
    return out


def _match(step: Mapping[str, Any], waiting: list[tuple[float, Mapping[str, Any], str]]
           ) -> tuple[float, Mapping[str, Any], str] | None:
    """The earliest send this step handles (same sender, target, handler and message)."""
    for i, (_, sent, sender) in enumerate(waiting):
        if (sender == step["sender"] and sent["target"] == step["node"]
                and sent["handler"] == step["handler"] and sent["args"] == step["args"]):
            return waiting.pop(i)
    return None


def _fields(changed: Any) -> str:
    if isinstance(changed, Mapping):
        return ", ".join(f"{k}={v}" for k, v in changed.items())
    return str(changed)


def _cut(text: str, limit: int = LABEL_CHARS) -> str:
    return text if len(text) <= limit else text[:limit - 3] + "..."


def changed_fields(walk: Mapping[str, Any]) -> list[dict[str, Any]]:
    """Each step's changed states reduced to the fields that changed (for notes)."""
    states = dict(walk["initial"])
    out = []
    for step in walk["steps"]:
        changes: dict[str, Any] = {}
        for node, state in step.get("changed", {}).items():
            before = states.get(node)
            if isinstance(before, Mapping) and isinstance(state, Mapping):
                changes[node] = {k: v for k, v in state.items() if before.get(k) != v}
            else:
                changes[node] = state
            states[node] = state
        out.append(changes)
    return out


def chart_of(walk: Mapping[str, Any]) -> Chart:
    """`layout` of a walk whose state changes are reduced to the fields that changed."""
    steps = [dict(s, changed=c) for s, c in zip(walk["steps"], changed_fields(walk), strict=True)]
    return layout(dict(walk, steps=steps))


def to_svg(chart: Chart) -> str:
    """The chart as an SVG document."""
    body = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{chart.width}" '
            f'height="{chart.height}" font-family="monospace" font-size="11">',
            f'<rect width="{chart.width}" height="{chart.height}" fill="white"/>',
            '<defs><marker id="head" markerWidth="8" markerHeight="8" refX="7" refY="4" '
            'orient="auto"><path d="M0,0 L8,4 L0,8 z"/></marker></defs>']
    for shape in chart.shapes:
        body.append(_svg(shape))
    body.append("</svg>")
    return "\n".join(body) + "\n"


def _rgb(colour: Sequence[int]) -> str:
    return f"rgb({colour[0]},{colour[1]},{colour[2]})"


def _svg(shape: Shape) -> str:
    match shape:
        case Line():
            head = ' marker-end="url(#head)"' if shape.arrow else ""
            return (f'<line x1="{shape.x1:.0f}" y1="{shape.y1:.0f}" x2="{shape.x2:.0f}" '
                    f'y2="{shape.y2:.0f}" stroke="{_rgb(shape.colour)}" '
                    f'stroke-width="{shape.width}"{head}/>')
        case Box():
            return (f'<rect x="{shape.x1:.0f}" y="{shape.y1:.0f}" '
                    f'width="{shape.x2 - shape.x1:.0f}" height="{shape.y2 - shape.y1:.0f}" '
                    f'fill="{_rgb(shape.fill)}" stroke="{_rgb(shape.outline)}"/>')
        case Text():
            return (f'<text x="{shape.x:.0f}" y="{shape.y + 10:.0f}" '
                    f'fill="{_rgb(shape.colour)}">{escape(shape.text)}</text>')
    raise TypeError(f"not a chart shape: {shape!r}")


def to_png(chart: Chart) -> Image.Image:
    """The chart as an RGB image."""
    img = Image.new("RGB", (chart.width, chart.height), WHITE)
    draw = ImageDraw.Draw(img)
    for shape in chart.shapes:
        match shape:
            case Line():
                draw.line([(shape.x1, shape.y1), (shape.x2, shape.y2)], fill=shape.colour,
                          width=shape.width)
                if shape.arrow:
                    _arrow_head(draw, shape)
            case Box():
                draw.rectangle([shape.x1, shape.y1, shape.x2, shape.y2], fill=shape.fill,
                               outline=shape.outline)
            case Text():
                draw.text((shape.x, shape.y), shape.text, fill=shape.colour)
    return img


def _arrow_head(draw: ImageDraw.ImageDraw, line: Line) -> None:
    dx, dy = line.x2 - line.x1, line.y2 - line.y1
    length = max((dx * dx + dy * dy) ** 0.5, 1.0)
    ux, uy = dx / length, dy / length
    back = (line.x2 - 8 * ux, line.y2 - 8 * uy)
    draw.polygon([(line.x2, line.y2), (back[0] - 4 * uy, back[1] + 4 * ux),
                  (back[0] + 4 * uy, back[1] - 4 * ux)], fill=line.colour)


def save_chart(walk: Mapping[str, Any], path: str | Path) -> Path:
    """Write the chart of `walk` to `path`: SVG for ``.svg``, else PNG."""
    path = Path(path)
    chart = chart_of(walk)
    if path.suffix.lower() == ".svg":
        path.write_text(to_svg(chart), encoding="utf-8")
    else:
        to_png(chart).save(path)
    return path
