"""Follow an RMC trace step by step in our checker's `rebeca` system; report the first difference.

RMC's message servers map to our nodes' handlers:

| RMC (owner.server)           | ours (node.handler)                 |
|------------------------------|-------------------------------------|
| theMap.SCANOBSTACLES         | map_server.scan_robot (scan timer)  |
| theMap.GENERATEPATH          | map_server.generate_path (service)  |
| theMap.UPDATEROBOTLOCATION   | map_server.on_pose                  |
| rK.ONLASERSCAN               | rK.on_scan                          |
| rK.ONNEWPATH                 | rK.on_path (the service's reply)    |
| rK.UPDATEMOVINGSTATUS        | rK.update_moving_status             |

At each RMC step the follower tries every enabled step of ours with that node
and handler (and every `ctx.choose` variant of it) and takes the one whose
result equals RMC's next state: every robot's cell, heading, velocity, waiting
flag, waits, failures, waypoint index, waypoints, targets, distance to the goal,
scan and `front_obstacle` (fields our state lacks are not compared), the map server's tracked poses and collision count, and every
pending message (due time, handler, arguments). RMC leaves open which of
several equal-time alternatives it took (five scans, five path requests); the
state after the step says it. When no candidate matches, the candidate with
the fewest differences is reported with both sides' values.

Run it on a case: `python3 -m tests.rmc.follower c2a` (from the repository root).
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tests.rmc import adapter
from tests.rmc.rmc_trace import (
    RMC_MAP,
    VIOLATION,
    MapView,
    Message,
    RmcState,
    RmcStep,
    RmcTrace,
    RobotView,
    decode_cell,
    decode_list,
    read_trace,
)

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data" / "rmc"
MAP_NODE = "map_server"

#: RMC message server (upper case, as in transitions) → our handler.
HANDLER_OF = {
    "SCANOBSTACLES": "scan_robot",
    "GENERATEPATH": "generate_path",
    "UPDATEROBOTLOCATION": "on_pose",
    "ONLASERSCAN": "on_scan",
    "ONNEWPATH": "on_path",
    "UPDATEMOVINGSTATUS": "update_moving_status",
}

ROBOT_FIELDS = ("cell", "dir", "velocity", "waiting", "waits", "failures", "move_idx", "moves",
                "targets", "distance", "obstacles", "front_obstacle")
MAP_FIELDS = ("cells", "dirs", "velocities", "collisions")


def node_of(rebec: str) -> str:
    """Our node name for an RMC rebec name."""
    return MAP_NODE if rebec == RMC_MAP else rebec


# ---------------------------------------------------------------- messages


def _rmc_values(args: str) -> list[Any]:
    quoted = re.sub(r"\b(r\d+|theMap)\b", r'"\1"', args)
    return json.loads(f"[{quoted}]".replace(", ]", "]"))  # RMC prints arrays as "[1, 2, ]"


def rmc_signature(msg: Message) -> tuple[Any, ...]:
    """A pending RMC message as (handler, comparable arguments)."""
    handler = HANDLER_OF.get(msg.server.upper(), msg.server)
    v = _rmc_values(msg.args)
    match handler:
        case "scan_robot":
            return handler, v[0]
        case "generate_path":
            return handler, v[0], (v[2], v[3]), (v[4], v[5])
        case "on_pose":
            return handler, f"r{v[0]}", (v[1], v[2]), v[3], v[4]
        case "on_scan" | "on_path":
            return handler, decode_list(v[0])
        case "update_moving_status":
            return handler, v[0]
    return (handler, *v)


def our_signature(handler: str, args: tuple[Any, ...]) -> tuple[Any, ...]:
    """One of our pending events as (handler, comparable arguments)."""
    match handler:
        case "scan_robot":
            return handler, args[0]
        case "generate_path":
            req = args[0]
            return handler, req.robot, tuple(req.start), tuple(req.goal)
        case "on_pose":
            pose = args[0]
            return handler, pose.robot, tuple(pose.cell), pose.direction, pose.velocity
        case "on_scan":
            return handler, tuple(tuple(c) for c in args[0].cells)
        case "on_path":
            cells = getattr(args[0], "cells", ())
            return handler, tuple(tuple(c) for c in cells)
        case "update_moving_status":
            return handler, args[0]
    return (handler, *args)


# ---------------------------------------------------------------- comparing


@dataclass(frozen=True)
class Difference:
    """One field that differs: where, our value, RMC's value."""

    where: str
    ours: Any
    rmc: Any

    def __str__(self) -> str:
        return f"{self.where}: ours {_short(self.ours)} | RMC {_short(self.rmc)}"


def _short(value: Any, limit: int = 400) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + " …"


def _norm(value: Any) -> Any:
    if isinstance(value, list | tuple):
        return tuple(_norm(v) for v in value)
    return value


def _fields(obj: Any, names: Iterable[str]) -> dict[str, Any]:
    return {n: _norm(getattr(obj, n)) for n in names if hasattr(obj, n)}


def compare(system: Any, world: Any, rmc: RmcState) -> list[Difference]:
    """Every difference between our world and an RMC state (robots, map server, queues)."""
    diffs: list[Difference] = []
    states = adapter.node_states(system, world)
    for name, view in rmc.robots.items():
        ours = _fields(states[name], ROBOT_FIELDS)
        theirs = _fields(view, ours)  # fields we do not model are not compared
        diffs += [Difference(f"{name}.{k}", ours[k], theirs[k]) for k in ours
                  if k in theirs and ours[k] != theirs[k]]
    ours_map = _fields(states[MAP_NODE], MAP_FIELDS)
    theirs_map = _fields(rmc.map, MAP_FIELDS)
    diffs += [Difference(f"{MAP_NODE}.{k}", ours_map[k], theirs_map[k]) for k in MAP_FIELDS
              if ours_map[k] != theirs_map[k]]
    diffs += _compare_queues(system, world, rmc)
    return diffs


def _compare_queues(system: Any, world: Any, rmc: RmcState) -> list[Difference]:
    ours: dict[str, list[tuple[Any, ...]]] = {}
    for p in adapter.pending(system, world):
        ours.setdefault(p.node, []).append((p.due, *our_signature(p.handler, p.args)))
    diffs = []
    for rebec, queue in rmc.queues.items():
        node = node_of(rebec)
        theirs = sorted((m.arrival, *rmc_signature(m)) for m in queue)
        mine = sorted(ours.get(node, []))
        if mine != theirs:
            only_ours = [e for e in mine if e not in theirs]
            only_rmc = [e for e in theirs if e not in mine]
            diffs.append(Difference(f"{node} pending (only on each side)", only_ours, only_rmc))
    return diffs


# ---------------------------------------------------------------- following


@dataclass
class Divergence:
    """The first RMC step we could not reproduce."""

    index: int
    step: RmcStep
    before: RmcState
    reason: str
    differences: list[Difference] = field(default_factory=list)
    candidates: list[str] = field(default_factory=list)

    def __str__(self) -> str:
        lines = [f"step {self.index}: RMC {self.step.owner}.{self.step.server} at t={self.before.now} "
                 f"({self.step.source} -> {self.step.target}): {self.reason}"]
        lines += [f"  tried: {c}" for c in self.candidates]
        lines += [f"  {d}" for d in self.differences]
        return "\n".join(lines)


@dataclass
class FollowResult:
    """How far the follower got: steps reproduced, the first divergence, the last world."""

    steps: int
    divergence: Divergence | None
    world: Any
    collisions: int

    @property
    def ok(self) -> bool:
        """True when every step was reproduced."""
        return self.divergence is None


def describe(step: adapter.Step) -> str:
    """A one-line description of one of our steps."""
    sig = our_signature(step.handler, step.args)
    return f"{step.node}.{step.handler} ({step.kind} t={step.due}) {_short(sig[1:], 120)} choices={step.choices}"


def follow(system: Any, world: Any, trace: RmcTrace,
           progress: Callable[[int, RmcStep], None] | None = None,
           violated: Callable[[Any, Any], bool] | None = None) -> FollowResult:
    """Drive `system` from `world` along `trace`; stop at the first difference.

    A violating trace's last step has no state after it; one of our candidates must
    then satisfy `violated(system, world)` (default: the map server counted a collision).
    """
    first = compare(system, world, trace.states[0])
    if first:
        step = trace.steps[0]
        return FollowResult(0, Divergence(-1, step, trace.states[0], "initial states differ", first),
                            world, 0)
    for i, step in enumerate(trace.steps):
        if progress is not None:
            progress(i, step)
        before = trace.states[i]
        node, handler = node_of(step.owner), HANDLER_OF.get(step.server)
        enabled = adapter.enabled_steps(system, world)
        candidates = [s for s in enabled if s.node == node and s.handler == handler]
        if not candidates:
            return FollowResult(i, Divergence(i, step, before, "no such step is enabled in ours",
                                              candidates=[describe(s) for s in enabled]), world, 0)
        if step.target == VIOLATION:
            return _last(system, world, i, step, before, candidates, violated or collided)
        after = trace.states[i + 1]
        best: tuple[int, list[Difference], adapter.Step] | None = None
        for cand in candidates:
            diffs = compare(system, adapter.take(cand), after)
            if not diffs:
                break
            if best is None or len(diffs) < best[0]:
                best = (len(diffs), diffs, cand)
        else:
            assert best is not None
            div = Divergence(i, step, before, f"no candidate reaches RMC's state {after.id} "
                             f"(closest: {describe(best[2])})", best[1],
                             [describe(c) for c in candidates])
            return FollowResult(i, div, world, 0)
        world = adapter.take(cand)
    return FollowResult(len(trace.steps), None, world, _collisions(system, world))


def _collisions(system: Any, world: Any) -> int:
    return adapter.node_states(system, world)[MAP_NODE].collisions


def collided(system: Any, world: Any) -> bool:
    """The model's `collisionFree` is broken: the map server counted a collision."""
    return _collisions(system, world) > 0


def _last(system: Any, world: Any, i: int, step: RmcStep, before: RmcState,
          candidates: list[adapter.Step], violated: Callable[[Any, Any], bool]) -> FollowResult:
    """RMC's last step broke its assertion: one of our candidates must break it too."""
    for cand in candidates:
        after = adapter.take(cand)
        if violated(system, after):
            return FollowResult(i + 1, None, after, _collisions(system, after))
    div = Divergence(i, step, before, "RMC's last step breaks its assertion; no candidate of ours does",
                     candidates=[describe(c) for c in candidates])
    return FollowResult(i, div, world, 0)


def trace_path(case: str) -> Path:
    """The RMC trace of a case (`c2a`, `c2b`, `c2c`) in tests/data/rmc."""
    return DATA / f"{case}.rmc-trace.jsonl.gz"


def scenario_path(case: str) -> Path:
    """Our scenario file for a case, under the `rebeca` profile and semantics."""
    return ROOT / "twinfleet" / "launch" / f"{case}_rebeca.yaml"


def follow_case(case: str) -> FollowResult:
    """Follow RMC's trace of `case` in our `launch/<case>_rebeca.yaml`."""
    system, world = adapter.build(scenario_path(case))
    return follow(system, world, read_trace(trace_path(case)))


def main(argv: list[str] | None = None) -> int:
    """Command line: follow one or more cases and print how far each got."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", nargs="+", help="c2a, c2b or c2c")
    args = ap.parse_args(argv)
    status = 0
    for case in args.cases:
        trace = read_trace(trace_path(case))
        result = follow_case(case)
        total = len(trace.steps)
        if result.ok:
            print(f"{case}: all {total} steps reproduced; collisions at the end: {result.collisions}")
        else:
            status = 1
            print(f"{case}: diverges after {result.steps} of {total} steps")
            print(result.divergence)
    return status


__all__ = ["Difference", "Divergence", "FollowResult", "MapView", "RobotView", "compare",
           "decode_cell", "follow", "follow_case", "main"]

if __name__ == "__main__":
    sys.exit(main())
