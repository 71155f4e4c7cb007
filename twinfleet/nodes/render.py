"""Pictures of the robot system: the map, robots, paths, shadows, scans and collisions.

`draw_world` draws one moment from plain values (`FleetView`); `view_of_states`
builds that view from node states (a scenario's start, or a step of a checker
trace). Pure apart from Pillow's in-memory image; writing files is the caller's.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from PIL import Image, ImageDraw

from twinfleet.nodes.grid import NB, Cell

PALETTE = ((220, 40, 40), (40, 90, 220), (30, 160, 60), (240, 140, 20), (150, 60, 190),
           (0, 170, 170), (200, 0, 120), (120, 120, 0))
FREE, OCCUPIED, COLLISION = (255, 255, 255), (60, 60, 60), (255, 0, 0)


def robot_colour(index: int) -> tuple[int, int, int]:
    """The colour of the `index`-th robot (stable across pictures)."""
    return PALETTE[index % len(PALETTE)]


@dataclass(frozen=True)
class RobotView:
    """One robot as drawn."""

    name: str
    cell: Cell | None  # None: not on the map yet
    direction: int
    start: Cell
    goal: Cell
    path: tuple[Cell, ...] = ()
    scan: tuple[Cell, ...] = ()


@dataclass(frozen=True)
class FleetView:
    """Everything one picture shows."""

    occupied: np.ndarray
    resolution: float
    robots: tuple[RobotView, ...]
    half_length: float = 0.22
    half_width: float = 0.22
    collision: tuple[str, str] | None = None
    scan_of: str | None = None
    caption: str = ""
    extra: Mapping[str, Any] = field(default_factory=dict)


LEGEND_PX = 18  # the band under the map: each robot's colour and name, then the symbols
LEGEND_SYMBOLS = "ring = start, cross = goal, line = plan, red ring = collision"


def draw_world(view: FleetView, cell_px: int = 12) -> Image.Image:
    """Render one moment of the fleet as an RGB image, `cell_px` pixels per cell: the map,
    each robot labelled with its name, then a legend band and the caption."""
    rows, cols = view.occupied.shape
    caption_px = 18 if view.caption else 0
    legend_px = LEGEND_PX if view.robots else 0
    img = Image.new("RGB", (cols * cell_px, rows * cell_px + legend_px + caption_px), FREE)
    pixels = np.where(view.occupied[..., None], OCCUPIED, FREE).astype(np.uint8)
    img.paste(Image.fromarray(np.repeat(np.repeat(pixels, cell_px, 0), cell_px, 1)), (0, 0))
    draw = ImageDraw.Draw(img)
    for i, robot in enumerate(view.robots):
        _draw_plan(draw, robot, robot_colour(i), cell_px)
    for i, robot in enumerate(view.robots):
        if robot.name == view.scan_of and robot.cell is not None:
            for hit in robot.scan:
                draw.line([_centre(robot.cell, cell_px), _centre(hit, cell_px)], fill=robot_colour(i), width=1)
    for i, robot in enumerate(view.robots):
        if robot.cell is not None:
            scale = cell_px / view.resolution
            corners = shadow_corners(robot.cell, robot.direction, view.half_length * scale,
                                     view.half_width * scale, cell_px)
            draw.polygon(corners, fill=robot_colour(i), outline=(0, 0, 0))
            tip = _centre(_step(robot.cell, robot.direction, 0.45), cell_px)
            draw.line([_centre(robot.cell, cell_px), tip], fill=(0, 0, 0), width=2)
    if view.collision:
        _draw_collision(draw, view, cell_px)
    _draw_labels(draw, view, cell_px)
    if legend_px:
        _draw_legend(draw, view, rows * cell_px)
    if view.caption:
        draw.text((4, rows * cell_px + legend_px + 3), view.caption, fill=(0, 0, 0))
    return img


def _draw_labels(draw: ImageDraw.ImageDraw, view: FleetView, cell_px: int) -> None:
    """Each robot's name beside its body (at its start while it is not on the map)."""
    for robot in view.robots:
        x, y = _centre(robot.cell if robot.cell is not None else robot.start, cell_px)
        draw.text((x + cell_px, y - cell_px * 1.6), robot.name, fill=(0, 0, 0),
                  stroke_width=1, stroke_fill=FREE)


def _draw_legend(draw: ImageDraw.ImageDraw, view: FleetView, top: int) -> None:
    """A swatch and the name of every robot, then what the symbols mean."""
    x = 4
    for i, robot in enumerate(view.robots):
        draw.rectangle([x, top + 4, x + 10, top + 14], fill=robot_colour(i), outline=(0, 0, 0))
        draw.text((x + 14, top + 3), robot.name, fill=(0, 0, 0))
        x += 20 + int(draw.textlength(robot.name))
    draw.text((x + 8, top + 3), LEGEND_SYMBOLS, fill=(90, 90, 90))


def _draw_plan(draw: ImageDraw.ImageDraw, robot: RobotView, colour: tuple[int, int, int],
               cell_px: int) -> None:
    light = tuple(int(c + (255 - c) * 0.45) for c in colour)
    if robot.path and robot.cell is not None:
        draw.line([_centre(c, cell_px) for c in (robot.cell, *robot.path)], fill=light, width=2)
    sx, sy = _centre(robot.start, cell_px)
    r = cell_px * 0.45
    draw.ellipse([sx - r, sy - r, sx + r, sy + r], outline=colour, width=2)
    gx, gy = _centre(robot.goal, cell_px)
    draw.line([gx - r, gy - r, gx + r, gy + r], fill=colour, width=2)
    draw.line([gx - r, gy + r, gx + r, gy - r], fill=colour, width=2)


def _draw_collision(draw: ImageDraw.ImageDraw, view: FleetView, cell_px: int) -> None:
    where = {r.name: r.cell for r in view.robots if r.cell is not None}
    centres = [_centre(where[n], cell_px) for n in view.collision or () if n in where]
    for x, y in centres:
        r = cell_px * 1.1
        draw.ellipse([x - r, y - r, x + r, y + r], outline=COLLISION, width=3)
    if len(centres) == 2:
        draw.line(centres, fill=COLLISION, width=3)


def _centre(cell: Sequence[float], cell_px: int) -> tuple[float, float]:
    # Grid (row, col) → image (x = column, y = row).
    return ((cell[1] + 0.5) * cell_px, (cell[0] + 0.5) * cell_px)


def _step(cell: Cell, direction: int, k: float) -> tuple[float, float]:
    dx, dy = NB[direction % 8]
    norm = math.hypot(dx, dy)
    return (cell[0] + k * dx / norm, cell[1] + k * dy / norm)


def shadow_corners(cell: Cell, direction: int, half_len_px: float, half_wid_px: float,
                   cell_px: int) -> list[tuple[float, float]]:
    """Image-space corners of a robot's rectangle (heading 45°·direction in grid space)."""
    dx, dy = NB[direction % 8]
    norm = math.hypot(dx, dy)
    u = (dy / norm, dx / norm)  # heading as an image vector (x = col, y = row)
    v = (-u[1], u[0])
    cx, cy = _centre(cell, cell_px)
    return [(cx + su * half_len_px * u[0] + sv * half_wid_px * v[0],
             cy + su * half_len_px * u[1] + sv * half_wid_px * v[1])
            for su, sv in ((1, 1), (1, -1), (-1, -1), (-1, 1))]


def _fleet_nodes(scenario: Any) -> tuple[Any, list[Any]]:
    servers = [c for c in scenario.nodes if hasattr(c.params, "robots")]
    if not servers:
        raise ValueError(f"{scenario.path}: no node of {scenario.name} serves a map with "
                         "robots on it, so there is no map to draw (a trace of it is drawn as "
                         "a sequence chart)")
    server = servers[0]
    robots = [scenario.node(name) for name in server.params.robots]
    return server, robots


def states_view(scenario: Any, states: Mapping[str, Any], *, collision: tuple[str, str] | None = None,
                scan_of: str | None = None, caption: str = "") -> FleetView:
    """The view of a scenario with the given node states (e.g. one step of a trace)."""
    server_cfg, robot_cfgs = _fleet_nodes(scenario)
    server = server_cfg.instantiate()
    views = []
    for cfg in robot_cfgs:
        st = states.get(cfg.name)
        cell = tuple(st.cell) if st is not None else tuple(cfg.params.start)
        views.append(RobotView(
            name=cfg.name, cell=cell, direction=st.dir if st is not None else cfg.params.initial_dir,
            start=tuple(cfg.params.start), goal=tuple(cfg.params.goal),
            path=tuple(st.moves[st.move_idx:]) if st is not None else (),
            scan=tuple(st.obstacles) if st is not None else ()))
    return FleetView(occupied=server.static, resolution=server.dims.res, robots=tuple(views),
                     half_length=server.dims.length / 2 + server.dims.collision_margin,
                     half_width=server.dims.width / 2 + server.dims.collision_margin,
                     collision=collision, scan_of=scan_of, caption=caption)


def scenario_view(scenario: Any, *, scan_of: str | None = None) -> FleetView:
    """The scenario at time 0: starts, goals, first plans (no robot known yet) and first scans."""
    from twinfleet.nodes.msgs import PathRequest
    from twinfleet.runtime.contract.context import Context
    from twinfleet.runtime.contract.dispatch import run_handler

    server_cfg, robot_cfgs = _fleet_nodes(scenario)
    server = server_cfg.instantiate()
    views = []
    for cfg in robot_cfgs:
        start, goal = tuple(cfg.params.start), tuple(cfg.params.goal)
        req = PathRequest(cfg.name, start, goal)
        out = run_handler(server, "generate_path", Context(server, 0), (req,), expects_reply=True)
        others = [tuple(c.params.start) for c in robot_cfgs if c is not cfg]
        views.append(RobotView(cfg.name, start, cfg.params.initial_dir, start, goal,
                               path=tuple(out.reply.cells) if out.reply else (),
                               scan=server.scanner.scan(start, cfg.params.initial_dir, others)))
    return FleetView(occupied=server.static, resolution=server.dims.res, robots=tuple(views),
                     half_length=server.dims.length / 2 + server.dims.collision_margin,
                     half_width=server.dims.width / 2 + server.dims.collision_margin,
                     scan_of=scan_of, caption=f"{scenario.name}: starts, goals and first plans")


def _as_state(value: Mapping[str, Any]) -> Any:
    from types import SimpleNamespace

    return SimpleNamespace(**value)


def trace_views(scenario: Any, trace: Mapping[str, Any], *, scan_of: str | None = None,
                every_step: bool = False) -> list[FleetView]:
    """One view per step of a checker trace (JSON), the last one showing the violation.

    Without `every_step`, only steps in which a robot's cell or heading changed,
    a fault was injected (a dropped message, a crash), and the last step, get a frame.
    """
    states = {name: _as_state(s) for name, s in trace["initial"]["states"].items()}
    views = [states_view(scenario, states, scan_of=scan_of, caption="t=0 ms: start")]
    steps = trace["steps"]
    for k, step in enumerate(steps):
        moved = False
        for name, value in step.get("changed", {}).items():
            old = states.get(name)
            states[name] = _as_state(value)
            moved |= old is None or getattr(old, "cell", None) != value.get("cell") \
                or getattr(old, "dir", None) != value.get("dir")
        last = k == len(steps) - 1
        if not (moved or every_step or last or step.get("faults")):
            continue
        collision = None
        server = next((s for s in states.values() if hasattr(s, "collided")), None)
        if last and server is not None and server.collided:
            collision = tuple(server.collided[-1])
        caption = f"t={step['time']} ms  step {step['index']}: {step['node']}.{step['handler']}"
        caption += "".join(f"  FAULT {fault}" for fault in step.get("faults") or ())
        if last:
            caption += f"  -- {trace.get('message', '')}"
        views.append(states_view(scenario, states, collision=collision, scan_of=scan_of,
                                 caption=caption[:110]))
    return views


def save_pictures(views: Sequence[FleetView], out: str, *, cell_px: int = 12,
                  frame_ms: int = 120) -> int:
    """Write one PNG (the last view) or an animated GIF (every view); return the frame count."""
    lower = out.lower()
    if lower.endswith(".gif"):
        frames = [draw_world(v, cell_px) for v in views]
        frames[0].save(out, save_all=True, append_images=frames[1:], duration=frame_ms, loop=0)
        return len(frames)
    if lower.endswith(".png"):
        draw_world(views[-1], cell_px).save(out)
        return 1
    raise ValueError(f"{out}: choose a .png (last moment) or .gif (every step) file name")
