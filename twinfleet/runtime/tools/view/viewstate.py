"""What the web viewer shows, as JSON-ready values: a live fleet's latest state, or a trace.

`LiveState` folds raw envelopes (the wire format of `runtime.contract.messages`, read
with plain msgpack, so no node code is imported) into what the page shows and
hands out the changes since the last call (`take_update`) for the page's
websocket. Every topic of any fleet, whatever its type, is listed with its
type, count and latest message (`topics`), which the page's topic list and
message inspector show.

What is drawn comes from the fleet's scene (`runtime.contract.scene`): each
envelope's data goes to `Scene.drawings`, and the drawings are folded into the
map, the bodies (their latest place, table row, scan, plan, start and goal,
and their trails), their order, and the collisions. The page draws those
kinds and knows no message type. A state made before its scene is known
(``scene_known=False``: a viewer that finds the fleet over Zenoh learns it
from the fleet, `runtime.tools.view.scene_finder`) keeps the envelopes that
arrive meanwhile and draws them once `set_scene` is called; a fleet without
a scene shows its topics only.

Append-only lists (trails, collisions, violations) travel as ``{"start": i,
"items": [...]}`` so that a change delivered twice is applied once. A fleet
launched again on the same endpoint shows as one sender's stamps going back:
that body's trail and fields start again, and its next update says
``"reset": true``.

`trace_document` turns a checker trace (``twinfleet-trace/1``) into what the
page steps through: the map that the scenario's nodes publish at start, and
for every step the scene's drawings of the node states (`Scene.state_drawings`),
as the changes from the step before, beside the node states themselves.
"""

from __future__ import annotations

import base64
from collections import deque
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, final

import msgpack

from twinfleet.runtime.contract import scene as draw
from twinfleet.runtime.contract.tracefile import load_trace
from twinfleet.runtime.host.keys import topic_in_fleet
from twinfleet.runtime.tools.forms.json_form import jsonable

MAX_TRAIL = 20_000
MAX_LOG = 500
MAX_WAITING = 20_000  # envelopes kept while the scene is not known yet
RESTART_MS = 1000  # one sender's stamps going back this far: the fleet was launched again
#: a body's fields on the page, by drawing kind
FIELDS: dict[type, str] = {draw.Body: "body", draw.Row: "row", draw.Scan: "scan",
                           draw.Plan: "path", draw.Start: "start", draw.Goal: "goal"}




def decode_envelope(payload: bytes) -> dict[str, Any] | None:
    """Decode a raw envelope (bytes stay bytes), or None if it is not one."""
    try:
        env = msgpack.unpackb(payload, raw=False, strict_map_key=False)
    except Exception:  # msgpack raises several unrelated types
        return None
    if not isinstance(env, dict) or not isinstance(env.get("type"), str) \
            or not isinstance(env.get("data"), dict):
        return None
    return env


def read_envelope(payload: bytes) -> dict[str, Any] | None:
    """Decode a raw envelope into a JSON-ready dict, or None if it is not one."""
    env = decode_envelope(payload)
    return None if env is None else jsonable(env)


def drawing_json(drawing: draw.Drawing) -> Any:
    """What the page gets of one drawing (a body's field, the map, a collision, the order)."""
    if isinstance(drawing, draw.Grid):
        return {"width": drawing.width, "height": drawing.height,
                "resolution": drawing.resolution, "origin": list(drawing.origin),
                "cells": base64.b64encode(drawing.cells).decode("ascii")}
    if isinstance(drawing, draw.Body):
        return {"x": drawing.x, "y": drawing.y, "theta": drawing.theta, "half_m": drawing.half_m}
    if isinstance(drawing, draw.Row):
        return dict(drawing.values)
    if isinstance(drawing, draw.Scan | draw.Plan):
        return [list(p) for p in drawing.points]
    if isinstance(drawing, draw.Start | draw.Goal):
        return list(drawing.point)
    if isinstance(drawing, draw.Collision):
        return {"points": [list(p) for p in drawing.points], "label": drawing.label,
                "caption": drawing.caption}
    if isinstance(drawing, draw.Order):
        return list(drawing.names)
    raise TypeError(f"not a drawing: {drawing!r}")


def fold(body: dict[str, Any], drawing: draw.Drawing) -> str:
    """Fold one of a body's drawings into its page entry; the field that changed.

    A row adds to the columns known; a body that does not say its heading keeps the
    last one (0, facing +x, when none is known)."""
    field = FIELDS[type(drawing)]
    value = drawing_json(drawing)
    if isinstance(drawing, draw.Row):
        value = {**body.get("row", {}), **value}
    elif isinstance(drawing, draw.Body) and drawing.theta is None:
        value["theta"] = body.get("body", {}).get("theta", 0.0)
    body[field] = value
    return field


@final
class _Log:
    """An append-only list with a cursor of what was already sent."""

    def __init__(self, limit: int) -> None:
        self.items: list[Any] = []
        self.offset = 0  # index of items[0] since the log started
        self.sent = 0
        self.limit = limit

    def add(self, item: Any) -> None:
        self.items.append(item)
        if len(self.items) > self.limit:
            drop = len(self.items) - self.limit
            del self.items[:drop]
            self.offset += drop

    def all(self) -> dict[str, Any]:
        return {"start": self.offset, "items": list(self.items)}

    def new(self) -> dict[str, Any] | None:
        end = self.offset + len(self.items)
        if self.sent >= end:
            return None
        first = max(self.sent, self.offset)
        self.sent = end
        return {"start": first, "items": self.items[first - self.offset:]}


@final
class LiveState:
    """The latest picture of one fleet, fed with raw samples on the asyncio loop.

    Args:
        fleet: the fleet to show; ``*`` shows the first fleet whose data arrives.
        scene: how to draw it (None: its topics only).
        scene_known: False until `set_scene` says how to draw the fleet (module docstring).
    """

    def __init__(self, fleet: str = "*", scene: draw.Scene | None = None, *,
                 scene_known: bool = True) -> None:
        self.fleet = fleet
        self.scene = scene
        self.waiting: deque[tuple[str, dict[str, Any]]] | None = (
            None if scene_known else deque(maxlen=MAX_WAITING))
        self.map: dict[str, Any] | None = None
        self.map_id: tuple[Any, ...] | None = None
        self.robots: dict[str, dict[str, Any]] = {}
        self.trails: dict[str, _Log] = {}
        self.order: list[str] = []
        self.ordered = False  # the scene gave the order (else: natural order of the names)
        self.collisions = _Log(MAX_LOG)
        self.violations = _Log(MAX_LOG)
        self.ended: str | None = None
        self.link = {"session": False, "router": False}
        self.counts: dict[str, int] = {}
        self.latest: dict[str, dict[str, Any]] = {}  # topic → its last envelope (JSON values)
        self._dirty_topics: set[str] = set()
        self.messages = 0
        self._stamps: dict[tuple[str, str], int] = {}  # (sender, body) → latest stamp
        self._reset: set[str] = set()  # bodies restarted since the last update
        self._dirty: dict[str, set[str]] = {}
        self._dirty_top: set[str] = set()

    @property
    def columns(self) -> list[str]:
        """The table's columns after a body's name."""
        return list(self.scene.columns) if self.scene is not None else []

    def set_scene(self, scene: draw.Scene | None) -> None:
        """Draw with `scene` from now on, and draw what arrived before it was known."""
        self.scene = scene
        waiting, self.waiting = self.waiting or (), None
        self._dirty_top.add("columns")
        for topic, env in waiting:
            self._apply(topic, env)

    def on_sample(self, key: str, payload: bytes) -> None:
        """Fold one sample of key `twinfleet/<fleet>/<topic>` into the state."""
        where = topic_in_fleet(self.fleet, key)
        if where is None:
            return
        fleet, topic = where.fleet, where.topic
        if self.fleet == "*":  # the first fleet whose data arrives is the one shown
            self.fleet = fleet
            self._dirty_top.add("fleet")
        self.messages += 1
        self.counts[topic] = self.counts.get(topic, 0) + 1
        env = decode_envelope(payload)
        shown = jsonable(env) if env is not None else {"type": "(undecodable)",
                                                       "data": {"bytes": len(payload)}}
        if shown != self.latest.get(topic):  # the same envelope again is a latched copy
            self.latest[topic] = shown
            self._dirty_topics.add(topic)
        if env is None:
            return
        if self.waiting is not None:
            self.waiting.append((topic, env))
        else:
            self._apply(topic, env)

    def _apply(self, topic: str, env: dict[str, Any]) -> None:
        kind, data = env["type"], env["data"]
        if kind == "twinfleet/Violation":
            self.violations.add(jsonable(data))
        elif kind == "std_msgs/String" and topic == "/twinfleet/shutdown":
            self.ended = str(data.get("data", ""))
            self._dirty_top.add("ended")
        elif self.scene is not None:
            self._draw(env, self.scene.drawings(topic, kind, data))

    def _draw(self, env: dict[str, Any], drawings: Sequence[draw.Drawing]) -> None:
        """Fold one message's drawings in, after checking its bodies for a new run."""
        named = dict.fromkeys(d.name for d in drawings if isinstance(d, draw.NAMED))
        for name in named:
            self._new_run_check(str(env.get("sender", "")), name, env.get("stamp_ms"))
        for drawing in drawings:
            if isinstance(drawing, draw.NAMED):
                self._body(drawing)
            elif isinstance(drawing, draw.Grid):
                self._grid(env, drawing)
            elif isinstance(drawing, draw.Collision):
                self.collisions.add(drawing_json(drawing))
            elif isinstance(drawing, draw.Order):
                self._order(list(drawing.names))

    def _grid(self, env: dict[str, Any], grid: draw.Grid) -> None:
        ident = (env.get("sender"), env.get("seq"), env.get("stamp_ms"), grid)
        if ident != self.map_id:  # the latched copy from history repeats the live one
            self.map, self.map_id = drawing_json(grid), ident
            self._dirty_top.add("map")

    def _order(self, names: list[str]) -> None:
        self.ordered = True
        if names and names != self.order:
            self.order = names
            self._dirty_top.add("order")

    def _new_run_check(self, sender: str, name: str, stamp: Any) -> None:
        """A sender's fleet clock jumping back means a new run of the fleet: restart the
        body's trail and fields. Only one sender's stamps are compared with each other: one
        node may publish drawings of another's body on its own clock, which may lag the
        body's own by seconds when it is busy (that restarted bodies mid-run)."""
        if not isinstance(stamp, int):
            return
        key = (sender, name)
        last = self._stamps.get(key)
        self._stamps[key] = stamp if last is None else max(stamp, last)
        if last is not None and stamp < last - RESTART_MS:
            self._stamps = {k: v for k, v in self._stamps.items() if k[1] != name}
            self._stamps[key] = stamp
            self.trails[name] = _Log(MAX_TRAIL)
            self.robots[name] = {}
            self._reset.add(name)
            if self.ended is not None:
                self.ended = None
                self._dirty_top.add("ended")

    def _body(self, drawing: draw.Drawing) -> None:
        name = drawing.name  # type: ignore[union-attr]
        robot = self.robots.setdefault(name, {})
        trail = self.trails.setdefault(name, _Log(MAX_TRAIL))
        field = fold(robot, drawing)
        if field == "body":
            here = [robot["body"]["x"], robot["body"]["y"]]
            if not trail.items or trail.items[-1] != here:
                trail.add(here)
        self._dirty.setdefault(name, set()).add(field)
        if name not in self.order and not self.ordered:
            self.order = sorted(self.robots, key=_natural)
            self._dirty_top.add("order")

    def set_link(self, session: bool, router: bool) -> None:
        """Record whether the Zenoh session is open and reaches a router."""
        if self.link != {"session": session, "router": router}:
            self.link = {"session": session, "router": router}
            self._dirty_top.add("link")

    def snapshot(self) -> dict[str, Any]:
        """Everything, for a page that just connected."""
        robots = {name: {**r, "trail": self.trails[name].all()} for name, r in self.robots.items()}
        return {"kind": "snapshot", "fleet": self.fleet, "map": self.map, "robots": robots,
                "order": self.order, "columns": self.columns,
                "collisions": self.collisions.all(), "violations": self.violations.all(),
                "ended": self.ended, "link": self.link, "stats": self._stats(),
                "topics": {t: self._topic(t) for t in sorted(self.latest)}}

    def _topic(self, topic: str) -> dict[str, Any]:
        """What the topic list and the inspector show of one topic."""
        last = self.latest[topic]
        return {"type": last.get("type"), "count": self.counts.get(topic, 0), "last": last}

    def take_update(self) -> dict[str, Any] | None:
        """The changes since the last call (None if nothing changed)."""
        robots = {}
        for name, fields in self._dirty.items():
            entry = {f: self.robots[name][f] for f in fields if f in self.robots[name]}
            if name in self._reset:  # the page drops what it holds of the body's last run
                entry["reset"] = True
            trail = self.trails[name].new()
            if trail:
                entry["trail"] = trail
            robots[name] = entry
        update: dict[str, Any] = {"kind": "update", "robots": robots}
        for name in self._dirty_top:
            update[name] = getattr(self, name)
        for name, log in (("collisions", self.collisions), ("violations", self.violations)):
            new = log.new()
            if new:
                update[name] = new
        if self._dirty_topics:
            update["topics"] = {t: self._topic(t) for t in sorted(self._dirty_topics)}
        changed = bool(robots) or len(update) > 2
        self._dirty.clear()
        self._reset.clear()
        self._dirty_top.clear()
        self._dirty_topics.clear()
        if not changed:
            return None
        update["stats"] = self._stats()
        return update

    def _stats(self) -> dict[str, Any]:
        return {"messages": self.messages, "topics": dict(sorted(self.counts.items()))}


def _natural(name: str) -> tuple[Any, ...]:
    head = name.rstrip("0123456789")
    tail = name[len(head):]
    return (head, int(tail) if tail else -1)


def trace_document(path: str | Path) -> dict[str, Any]:
    """The page's view of a checker trace: the map, the node states and each step's changes,
    and what the scenario's scene draws at each step (`frames`)."""
    from twinfleet.runtime.scenario.overrides import load_with_params
    from twinfleet.runtime.scenario.scenes import load_scene

    trace = load_trace(path)
    scenario = load_with_params(trace["scenario"], trace.get("params") or ())
    scene = load_scene(scenario.scene) if scenario.scene else None
    initial: Mapping[str, Any] = trace["initial"]["states"]
    keep = ("index", "time", "node", "handler", "kind", "args", "changed", "logs", "failure",
            "faults")  # the faults too: a dropped message is why something never arrives
    steps = [{k: s.get(k) for k in keep} for s in trace["steps"]]
    return {"kind": "trace", "file": str(path), "scenario": scenario.name,
            "message": trace.get("message", ""), "property": trace.get("property"),
            "shape": trace.get("shape"), "cycle_start": trace.get("cycle_start"),
            "map": start_map(scenario, scene), "columns": list(scene.columns) if scene else [],
            "frames": trace_frames(scenario, scene, initial, steps), "initial": initial,
            "steps": steps}


def trace_frames(scenario: Any, scene: draw.Scene | None, initial: Mapping[str, Any],
                 steps: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """What `scene` draws of the initial states and after each step: the first frame whole,
    then each frame as its changes from the one before (bodies by name, the order and the
    collisions when they differ)."""
    from twinfleet.runtime.host.introspect import plain_value

    names = [cfg.name for cfg in scenario.nodes]
    params = {cfg.name: plain_value(cfg.params) for cfg in scenario.nodes}
    params = {name: values for name, values in params.items() if isinstance(values, dict)}
    states = dict(initial)
    frames: list[dict[str, Any]] = []
    last: dict[str, Any] = {"order": None, "robots": {}, "collisions": None}
    for step in [{}, *steps]:
        states.update(step.get("changed") or {})
        ordered = {n: states[n] for n in names if n in states}
        frame = _frame(scene.state_drawings(ordered, params) if scene is not None else ())
        change: dict[str, Any] = {"robots": {n: e for n, e in frame["robots"].items()
                                             if last["robots"].get(n) != e}}
        change.update({k: frame[k] for k in ("order", "collisions") if frame[k] != last[k]})
        frames.append(change)
        last = frame
    return frames


def _frame(drawings: Sequence[draw.Drawing]) -> dict[str, Any]:
    """One state's drawings folded as the page holds them."""
    frame: dict[str, Any] = {"order": [], "robots": {}, "collisions": []}
    for drawing in drawings:
        if isinstance(drawing, draw.NAMED):
            fold(frame["robots"].setdefault(drawing.name, {}), drawing)
        elif isinstance(drawing, draw.Collision):
            frame["collisions"].append(drawing_json(drawing))
        elif isinstance(drawing, draw.Order):
            frame["order"] = list(drawing.names)
    return frame


def start_map(scenario: Any, scene: draw.Scene | None) -> dict[str, Any] | None:
    """The map that the scenario's nodes publish at start, as the page gets it (None without
    a scene, or when no start publication draws a grid)."""
    from twinfleet.runtime.contract.context import Context, Publish
    from twinfleet.runtime.contract.dispatch import run_handler
    from twinfleet.runtime.contract.messages import encode
    from twinfleet.runtime.contract.node import NodeSpec

    if scene is None:
        return None
    for cfg in scenario.nodes:
        node = None
        for spec in NodeSpec.of(cfg.cls).of_kind("start"):
            node = node or cfg.instantiate()
            outcome = run_handler(node, spec.method, Context(node, 0))
            for effect in outcome.effects:
                if not isinstance(effect, Publish):
                    continue
                env = decode_envelope(encode(effect.msg))
                if env is None:
                    continue
                grids = [d for d in scene.drawings(effect.topic, env["type"], env["data"])
                         if isinstance(d, draw.Grid)]
                if grids:
                    return drawing_json(grids[0])
    return None

