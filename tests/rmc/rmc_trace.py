"""Reader for the Rebeca model checker's counterexample traces (`*.rmc-trace.jsonl.gz`).

The traces are RMC's own output on the paper's public model, compacted from its
XML report (the build and the cases: `tests/data/rmc/README.md`). Line 1 is a header; then states and the transitions taken
from them alternate. A state names every rebec's variables (the model's names)
and queue; cells are encoded by the model's `xy2idx` (see `decode_cell`).

The reader turns each state into plain values named like our robot system
(cell, dir, velocity, waiting, ...), so a follower can compare them field by
field; it knows nothing about the checker.
"""

from __future__ import annotations

import gzip
import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

Cell = tuple[int, int]

#: RMC's map server rebec; our scenario calls it `map_server`.
RMC_MAP = "theMap"
#: The last "state" of a violating trace: the transition that broke the property.
VIOLATION = "assertion failed"

_MSG = re.compile(r"^(\w+)\((.*)\)$")


def decode_cell(code: int) -> Cell:
    """The model's `idx2xy`: code = ey·10000 + ex, e = 1000·s + |v|, s = 1 (≥ 0) or 2 (< 0)."""
    ex, ey = code % 10000, code // 10000
    x, y = ex % 1000, ey % 1000
    return (-x if ex // 1000 == 2 else x, -y if ey // 1000 == 2 else y)


def decode_list(arr: list[int]) -> tuple[Cell, ...]:
    """A model buffer (element 0 = count, then encoded cells) as cells."""
    return tuple(decode_cell(v) for v in arr[1:1 + arr[0]])


@dataclass(frozen=True, slots=True)
class RobotView:
    """One robot's variables, named as in our `RobotState` (plus two the model keeps)."""

    cell: Cell
    dir: int
    velocity: int
    waiting: bool
    waits: int
    failures: int
    move_idx: int
    moves: tuple[Cell, ...]
    targets: tuple[Cell, ...]
    distance: int
    obstacles: tuple[Cell, ...]
    front_obstacle: int


@dataclass(frozen=True, slots=True)
class MapView:
    """The map server's variables: last reported pose per robot, collision count."""

    cells: tuple[Cell, ...]
    dirs: tuple[int, ...]
    velocities: tuple[int, ...]
    collisions: int


@dataclass(frozen=True, slots=True)
class Message:
    """A queued message: arrival time (ms), message server, sender, raw argument text."""

    arrival: int
    server: str
    sender: str
    args: str


@dataclass(frozen=True, slots=True)
class RmcState:
    """One state of the trace: its time, every robot, the map server and every queue."""

    id: str
    now: int
    robots: dict[str, RobotView]
    map: MapView
    queues: dict[str, tuple[Message, ...]]


@dataclass(frozen=True, slots=True)
class RmcStep:
    """A transition: which rebec (`owner`) ran which message server (`server`, upper case)."""

    source: str
    target: str
    owner: str
    server: str
    sender: str
    time: int


@dataclass(frozen=True, slots=True)
class RmcTrace:
    """A whole trace: header, the states in order, and the step taken from each."""

    header: dict[str, Any]
    states: tuple[RmcState, ...]
    steps: tuple[RmcStep, ...]

    @property
    def violated(self) -> bool:
        """True when the last step ends in a violated assertion (no state after it)."""
        return bool(self.steps) and self.steps[-1].target == VIOLATION


def _robot(s: dict[str, Any]) -> RobotView:
    return RobotView(cell=(s["rx"], s["ry"]), dir=s["rdir"], velocity=s["velocity"],
                     waiting=s["isWaiting"], waits=s["waits"], failures=s["failures"],
                     move_idx=s["moveidx"], moves=decode_list(s["moves"]),
                     targets=decode_list(s["targets"]), distance=s["distance2target"],
                     obstacles=decode_list(s["obstacles"]), front_obstacle=s["front_obstacle"])


def _map(s: dict[str, Any]) -> MapView:
    rloc = s["rloc"]
    n = rloc[0]
    slots = [rloc[4 * i + 1:4 * i + 5] for i in range(n)]
    return MapView(cells=tuple((x, y) for x, y, _, _ in slots), dirs=tuple(d for _, _, d, _ in slots),
                   velocities=tuple(v for _, _, _, v in slots), collisions=s["collisions"])


def _message(m: dict[str, Any]) -> Message:
    match = _MSG.match(m["msg"])
    server, args = (match.group(1), match.group(2)) if match else (m["msg"], "")
    return Message(int(m["arrival"]), server, m["sender"], args)


def _state(doc: dict[str, Any]) -> RmcState:
    rebecs = doc["rebecs"]
    robots = {name: _robot(r["state"]) for name, r in rebecs.items() if name != RMC_MAP}
    queues = {name: tuple(_message(m) for m in r["queue"]) for name, r in rebecs.items()}
    now = max(r["now"] for r in rebecs.values())
    return RmcState(doc["state"], now, robots, _map(rebecs[RMC_MAP]["state"]), queues)


def _step(doc: dict[str, Any]) -> RmcStep:
    source, target = doc["transition"]
    return RmcStep(source, target, doc["owner"], doc["msg"], doc["sender"], int(doc["time"]))


def read_trace(path: str | Path) -> RmcTrace:
    """Read a `.rmc-trace.jsonl.gz` file.

    Raises:
        ValueError: the states and steps do not alternate as the format says.
    """
    with gzip.open(path, "rt") as f:
        docs = [json.loads(line) for line in f if line.strip()]
    header, rest = docs[0], docs[1:]
    # A violating trace ends with a "state" line for the violation itself, with no rebecs.
    states = tuple(_state(d) for d in rest if "state" in d and d["rebecs"])
    steps = tuple(_step(d) for d in rest if "transition" in d)
    for i, step in enumerate(steps):
        if step.source != states[i].id or (i + 1 < len(states) and step.target != states[i + 1].id):
            raise ValueError(f"{path}: step {i} goes {step.source} -> {step.target}, "
                             f"not from state {states[i].id}")
    if len(steps) not in (len(states) - 1, len(states)):
        raise ValueError(f"{path}: {len(states)} states but {len(steps)} steps")
    return RmcTrace(header, states, steps)
