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

A message still in flight is drawn too: sent and not handled by the end of the
trace (or of the window drawn), its arrow is dashed grey and ends at the foot on
its target's lifeline, labelled ``in flight``; one handled after the window ends
there labelled with the step that handles it, one sent before the window starts at
the top labelled with the step that sent it. A long trace stays readable: `pages`
cuts it into windows of `PAGE_STEPS` steps (`save_chart` writes one file per
page), and a window (``render --steps A..B``) draws those steps only.
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
PAGE_STEPS: Final = 60  # steps per page of a long chart (about 2,200 px high)


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
    dashed: bool = False


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


Window = tuple[int, int]
"""Steps drawn, 1-based and inclusive: ``(first, last)``."""

_Send = tuple[int, float, Mapping[str, Any], str]  # (step index, row y, sent event, sender)


def layout(walk: Mapping[str, Any], window: Window | None = None) -> Chart:
    """The chart of a walked trace, or of the steps in `window` (module docstring)."""
    nodes, steps = list(walk["nodes"]), list(walk["steps"])
    first, last = window or (1, len(steps))
    rows = last - first + 1
    x = {n: LEFT_PX + COLUMN_PX * (i + 0.5) for i, n in enumerate(nodes)}
    height = TOP_PX + ROW_PX * (rows + 2) + 20
    foot = TOP_PX + ROW_PX * (rows + 1)
    shapes: list[Shape] = []
    for n in nodes:
        shapes.append(Text(x[n] - 4 * len(n), 10, n))
        shapes.append(Line(x[n], TOP_PX - 8, x[n], foot, GREY))
    waiting: list[_Send] = []
    for k, step in enumerate(steps, 1):
        y = TOP_PX + ROW_PX * (k - first + 1) if first <= k <= last else None
        sent = _match(step, waiting)
        if y is not None:
            shapes += _step_shapes(step, y, x, violating=k == len(steps))
            shapes += _arrow(step, sent, y, x, top=first)
        elif sent is not None and k > last and first <= sent[0] <= last:  # handled later
            shapes += _flight(sent, x, step["node"], foot, f"handled at step {k}")
        waiting += [(k, y if y is not None else float(TOP_PX), s, step["node"])
                    for s in step["sent"] if s["target"] != step["node"]]
    shapes += _in_flight([sent for sent in waiting if first <= sent[0] <= last], x, foot)
    shapes.append(Text(8, foot + 6, _foot(walk, first, last), RED))
    width = int(LEFT_PX + COLUMN_PX * len(nodes) + NOTE_PX)
    return Chart(width, height, tuple(shapes), tuple(nodes))


def _foot(walk: Mapping[str, Any], first: int, last: int) -> str:
    total = len(walk["steps"])
    said = f"violated: {walk['property']}: {walk['message']}"
    return said if last == total else (f"steps {first}..{last} of {total}; at step {total}, "
                                       f"{said}")


def _step_shapes(step: Mapping[str, Any], y: float, x: Mapping[str, float], *,
                 violating: bool) -> list[Shape]:
    node = step["node"]
    colour = RED if violating or step.get("failure") else BLUE
    out: list[Shape] = [Text(6, y - 6, f"t={step['time']}", GREY),
                        Box(x[node] - 7, y - 9, x[node] + 7, y + 9, BOX_FILL, colour),
                        Text(x[node] + 10, y - 16, f"{step['index']}. {step['handler']}", colour)]
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


def _arrow(step: Mapping[str, Any], sent: _Send | None, y: float, x: Mapping[str, float], *,
           top: int) -> list[Shape]:
    """The arrow of the message `step` handles, from its send (the window's top when it was
    sent before the window), its label beside the receiving end."""
    if sent is None:
        return []
    k, y0, _, sender = sent
    node = step["node"]
    label = f"{step['name'] or step['kind']}: {step['args']}"
    if k < top:
        label = f"(step {k}) {label}"
    right = x[sender] < x[node]
    out: list[Shape] = [Line(x[sender], y0, x[node] + (-8 if right else 8), y, BLACK,
                             arrow=True)]
    text = _cut(label)
    start = x[node] - 12 - 6 * len(text) if right else x[node] + 12
    out.append(Text(start, y + 4, text, BLACK))
    return out


def _flight(sent: _Send, x: Mapping[str, float], target: str, foot: float,
            what: str) -> list[Shape]:
    """A message not handled within the window: dashed, to its target's lifeline at the foot."""
    k, y0, event, sender = sent
    if target not in x or sender not in x:
        return []
    label = _cut(f"{what}: {event.get('name') or event.get('kind', '')} (step {k})")
    return [Line(x[sender], y0, x[target], foot - 4, GREY, arrow=True, dashed=True),
            Text(x[target] + 12, foot - 18, label, GREY)]


def _in_flight(sends: list[_Send], x: Mapping[str, float], foot: float) -> list[Shape]:
    """Messages never handled: each one's dashed arrow, one label per target."""
    out: list[Shape] = []
    by_target: dict[str, list[_Send]] = {}
    for sent in sends:
        by_target.setdefault(sent[2]["target"], []).append(sent)
    for target, group in by_target.items():
        if len(group) == 1:
            out += _flight(group[0], x, target, foot, "in flight")
            continue
        out += [s for sent in group for s in _flight(sent, x, target, foot, "")
                if isinstance(s, Line)]
        if target in x:
            steps = ", ".join(str(sent[0]) for sent in group)
            out.append(Text(x[target] + 12, foot - 18,
                            _cut(f"in flight: {len(group)} (steps {steps})"), GREY))
    return out


def pages(total: int, window: Window | None = None, per_page: int = PAGE_STEPS) -> list[Window]:
    """The windows a chart of `total` steps is drawn in: `window` alone, else pages of
    `per_page` steps (one page for a short trace)."""
    if window is not None:
        return [window]
    return [(a, min(a + per_page - 1, total)) for a in range(1, max(total, 1) + 1, per_page)]


def _match(step: Mapping[str, Any], waiting: list[_Send]) -> _Send | None:
    """The earliest send this step handles (same sender, target, handler and message)."""
    for i, (_, _, sent, sender) in enumerate(waiting):
        if (sender == step["sender"] and sent["target"] == step["node"]
                and sent["handler"] == step["handler"] and _same(sent["args"], step["args"])):
            return waiting.pop(i)
    return None


def _same(sent: Any, handled: Any) -> bool:
    """Whether a sent message's arguments are the handled one's (the walk shortens a long
    sent message to its first characters and ``...``)."""
    if isinstance(sent, str) and isinstance(handled, str) and sent.endswith("..."):
        return handled.startswith(sent[:-3])
    return bool(sent == handled)


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


def chart_of(walk: Mapping[str, Any], window: Window | None = None) -> Chart:
    """`layout` of a walk whose state changes are reduced to the fields that changed."""
    steps = [dict(s, changed=c) for s, c in zip(walk["steps"], changed_fields(walk), strict=True)]
    return layout(dict(walk, steps=steps), window)


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
            dash = ' stroke-dasharray="6,4"' if shape.dashed else ""
            return (f'<line x1="{shape.x1:.0f}" y1="{shape.y1:.0f}" x2="{shape.x2:.0f}" '
                    f'y2="{shape.y2:.0f}" stroke="{_rgb(shape.colour)}" '
                    f'stroke-width="{shape.width}"{dash}{head}/>')
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
                for a, b in _dashes(shape) if shape.dashed else [((shape.x1, shape.y1),
                                                                   (shape.x2, shape.y2))]:
                    draw.line([a, b], fill=shape.colour, width=shape.width)
                if shape.arrow:
                    _arrow_head(draw, shape)
            case Box():
                draw.rectangle([shape.x1, shape.y1, shape.x2, shape.y2], fill=shape.fill,
                               outline=shape.outline)
            case Text():
                draw.text((shape.x, shape.y), shape.text, fill=shape.colour)
    return img


def _dashes(line: Line, on: float = 6.0, off: float = 4.0
            ) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """The drawn pieces of a dashed line (SVG's ``stroke-dasharray`` 6,4)."""
    dx, dy = line.x2 - line.x1, line.y2 - line.y1
    length = max((dx * dx + dy * dy) ** 0.5, 1.0)
    out, d = [], 0.0
    while d < length:
        e = min(d + on, length)
        out.append(((line.x1 + dx * d / length, line.y1 + dy * d / length),
                    (line.x1 + dx * e / length, line.y1 + dy * e / length)))
        d = e + off
    return out


def _arrow_head(draw: ImageDraw.ImageDraw, line: Line) -> None:
    dx, dy = line.x2 - line.x1, line.y2 - line.y1
    length = max((dx * dx + dy * dy) ** 0.5, 1.0)
    ux, uy = dx / length, dy / length
    back = (line.x2 - 8 * ux, line.y2 - 8 * uy)
    draw.polygon([(line.x2, line.y2), (back[0] - 4 * uy, back[1] + 4 * ux),
                  (back[0] + 4 * uy, back[1] - 4 * ux)], fill=line.colour)


def save_chart(walk: Mapping[str, Any], path: str | Path,
               window: Window | None = None) -> list[Path]:
    """Write the chart of `walk` to `path` (SVG for ``.svg``, else PNG): the steps of
    `window`, else every step, a long trace as pages ``NAME-1.png``, ``NAME-2.png``, ...
    (`pages`); the files written."""
    path = Path(path)
    windows = pages(len(walk["steps"]), window)
    written = []
    for i, part in enumerate(windows, 1):
        out = path if len(windows) == 1 else path.with_name(f"{path.stem}-{i}{path.suffix}")
        chart = chart_of(walk, part)
        if out.suffix.lower() == ".svg":
            out.write_text(to_svg(chart), encoding="utf-8")
        else:
            to_png(chart).save(out)
        written.append(out)
    return written
