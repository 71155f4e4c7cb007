"""What the web viewer shows, as JSON-ready values: a live fleet's latest state, or a trace.

`LiveState` folds raw envelopes (the wire format of `runtime.contract.messages`, read
with plain msgpack, so no node code is imported) into the latest map, poses,
statuses, scans, collisions and violations, and hands out the changes since
the last call (`take_update`) for the page's websocket. Append-only lists
(trails, collisions, violations) travel as ``{"start": i, "items": [...]}``
so that a change delivered twice is applied once. A fleet launched again on
the same endpoint shows as one sender's stamps going back: that robot's trail
and fields start again, and its next update says ``"reset": true``.

`trace_document` turns a checker trace (``twinfleet-trace/1``) into what the
page steps through: the map (the ``/map`` message the scenario's nodes publish
at start), the robots' starts and goals, the initial node states and each
step's changed states.

Message kinds are recognised by envelope type name, the ones of `nodes.msgs`
and `runtime.contract.messages`, and drawn; every topic of any fleet, whatever its
type, is listed with its type, count and latest message (`topics`), which the
page's topic list and message inspector show.
"""

from __future__ import annotations

import base64
from collections.abc import Mapping
from pathlib import Path
from typing import Any, final

import msgpack

from twinfleet.runtime.contract.tracefile import load_trace
from twinfleet.runtime.host.keys import topic_in_fleet

MAX_TRAIL = 20_000
MAX_LOG = 500
RESTART_MS = 1000  # one sender's stamps going back this far: the fleet was launched again
ROBOT_TYPES = {
    "twinfleet_msgs/RobotPose": "pose",
    "twinfleet_msgs/RobotStatus": "status",
    "twinfleet_msgs/ObstacleScan": "scan",
}


def jsonable(value: Any) -> Any:
    """Msgpack-decoded data → JSON values: bytes become base64 text, tuples lists."""
    if isinstance(value, bytes | bytearray):
        return base64.b64encode(value).decode("ascii")
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    return value


def read_envelope(payload: bytes) -> dict[str, Any] | None:
    """Decode a raw envelope into a JSON-ready dict, or None if it is not one."""
    try:
        env = msgpack.unpackb(payload, raw=False, strict_map_key=False)
    except Exception:  # msgpack raises several unrelated types
        return None
    if not isinstance(env, dict) or not isinstance(env.get("type"), str) \
            or not isinstance(env.get("data"), dict):
        return None
    return jsonable(env)


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
    """

    def __init__(self, fleet: str = "*") -> None:
        self.fleet = fleet
        self.map: dict[str, Any] | None = None
        self.map_id: tuple[Any, ...] | None = None
        self.robots: dict[str, dict[str, Any]] = {}
        self.trails: dict[str, _Log] = {}
        self.order: list[str] = []
        self.collisions = _Log(MAX_LOG)
        self.violations = _Log(MAX_LOG)
        self.fleet_status: dict[str, Any] | None = None
        self.ended: str | None = None
        self.link = {"session": False, "router": False}
        self.counts: dict[str, int] = {}
        self.latest: dict[str, dict[str, Any]] = {}  # topic → its last envelope (JSON values)
        self._dirty_topics: set[str] = set()
        self.messages = 0
        self._stamps: dict[tuple[str, str], int] = {}  # (sender, robot) → latest stamp
        self._reset: set[str] = set()  # robots restarted since the last update
        self._dirty: dict[str, set[str]] = {}
        self._dirty_top: set[str] = set()

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
        env = read_envelope(payload)
        shown = env if env is not None else {"type": "(undecodable)",
                                             "data": {"bytes": len(payload)}}
        if shown != self.latest.get(topic):  # the same envelope again is a latched copy
            self.latest[topic] = shown
            self._dirty_topics.add(topic)
        if env is not None:
            self._apply(topic, env)

    def _apply(self, topic: str, env: dict[str, Any]) -> None:
        kind, data = env["type"], env["data"]
        field = ROBOT_TYPES.get(kind)
        if field is not None and isinstance(data.get("robot"), str):
            self._new_run_check(str(env.get("sender", "")), data["robot"], env.get("stamp_ms"))
            self._robot(data["robot"], field, data)
        elif kind == "twinfleet_msgs/Path" and topic.count("/") == 2 and topic.endswith("/path"):
            self._robot(topic.split("/")[1], "path", data)  # /<robot>/path: its latest plan
        elif kind == "twinfleet_msgs/OccupancyGrid":
            ident = (env.get("sender"), env.get("seq"), env.get("stamp_ms"), data.get("data"))
            if ident != self.map_id:  # the latched copy from history repeats the live one
                self.map, self.map_id = data, ident
                self._dirty_top.add("map")
        elif kind == "twinfleet_msgs/Collision":
            self.collisions.add(data)
        elif kind == "twinfleet_msgs/FleetStatus":
            self.fleet_status = data
            self._dirty_top.add("fleet_status")
            robots = [r for r in data.get("robots", []) if isinstance(r, str)]
            if robots and robots != self.order:
                self.order = robots
                self._dirty_top.add("order")
        elif kind == "twinfleet/Violation":
            self.violations.add(data)
        elif kind == "std_msgs/String" and topic == "/twinfleet/shutdown":
            self.ended = str(data.get("data", ""))
            self._dirty_top.add("ended")

    def _new_run_check(self, sender: str, name: str, stamp: Any) -> None:
        """A sender's fleet clock jumping back means a new run of the fleet: restart the
        robot's trail and fields. Only one sender's stamps are compared with each other: the
        map server publishes the robots' scans on its own clock, which may lag theirs by
        seconds when it is busy (that restarted robots mid-run)."""
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

    def _robot(self, name: str, field: str, data: dict[str, Any]) -> None:
        robot = self.robots.setdefault(name, {})
        trail = self.trails.setdefault(name, _Log(MAX_TRAIL))
        if field in ("scan", "path"):
            robot[field] = data.get("cells", [])
        else:
            robot[field] = data
        if field == "pose" and (not trail.items or trail.items[-1] != data.get("cell")):
            trail.add(data.get("cell"))
        self._dirty.setdefault(name, set()).add(field)
        if name not in self.order and not self.fleet_status:
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
                "order": self.order, "collisions": self.collisions.all(),
                "violations": self.violations.all(), "fleet_status": self.fleet_status,
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
            if name in self._reset:  # the page drops what it holds of the robot's last run
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
    """The page's view of a checker trace: map, robots, initial states and steps."""
    from twinfleet.runtime.scenario.spec import load_scenario

    trace = load_trace(path)
    scenario = load_scenario(trace["scenario"], {"profile": trace.get("profile", "fixed")})
    initial: Mapping[str, Any] = trace["initial"]["states"]
    robots = []
    for cfg in scenario.nodes:
        state = initial.get(cfg.name)
        if isinstance(state, Mapping) and "cell" in state:
            robots.append({"name": cfg.name, "start": list(getattr(cfg.params, "start", state["cell"])),
                           "goal": list(getattr(cfg.params, "goal", state["cell"]))})
    keep = ("index", "time", "node", "handler", "kind", "args", "changed", "logs", "failure")
    return {"kind": "trace", "file": str(path), "scenario": scenario.name,
            "message": trace.get("message", ""), "property": trace.get("property"),
            "shape": trace.get("shape"), "cycle_start": trace.get("cycle_start"),
            "map": start_map(scenario), "robots": robots, "initial": initial,
            "steps": [{k: s.get(k) for k in keep} for s in trace["steps"]]}


def start_map(scenario: Any) -> dict[str, Any] | None:
    """The ``/map`` message that the scenario's nodes publish at start, as JSON data."""
    from twinfleet.runtime.contract.context import Context, Publish
    from twinfleet.runtime.contract.dispatch import run_handler
    from twinfleet.runtime.contract.messages import encode
    from twinfleet.runtime.contract.node import NodeSpec

    for cfg in scenario.nodes:
        node = None
        for spec in NodeSpec.of(cfg.cls).of_kind("start"):
            node = node or cfg.instantiate()
            outcome = run_handler(node, spec.method, Context(node, 0))
            for effect in outcome.effects:
                if isinstance(effect, Publish) and effect.topic == "/map":
                    env = read_envelope(encode(effect.msg))
                    return env["data"] if env else None
    return None
