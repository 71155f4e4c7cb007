"""What a viewer draws of a fleet: the `Scene` a scenario names, and the drawings it hands out.

The framework's viewers (`twinfleet view`, `twinfleet foxglove`, `twinfleet
export`) know no message type of any fleet. They list every topic whatever
it carries; to draw a picture they ask the fleet's scene, an object the
scenario names by import name (``scene: mypkg.drawing:MyScene``)
that turns what the fleet publishes, and in a checker trace the node states,
into the small frozen values below. A fleet without a scene is shown as its
topics only.

Places are in map cells, as fractions: ``x`` runs along the grid's columns,
``y`` along its rows, and the centre of cell (row r, column c) is
``(c + 0.5, r + 0.5)``; the grid's resolution and origin place them in
metres. A heading ``theta`` is in radians from +x towards +y. Sizes are
metres. Places are kept in cells because messages may say where a robot is
before the map that gives the cells a size has arrived.

A scene must be cheap to build (the viewer makes one with no arguments) and
must not fail on a message of an unexpected shape: it returns no drawing.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

Point = tuple[float, float]


@dataclass(frozen=True)
class Grid:
    """An occupancy grid: row-major cells, 0 free .. 100 occupied, 255 unknown (-1 as int8)."""

    width: int
    height: int
    resolution: float  # metres per cell
    origin: Point  # metres: where the grid's corner lies
    cells: bytes


@dataclass(frozen=True)
class Body:
    """Where a body (a robot) is. `theta` None: this message does not say its heading; the
    web viewer keeps the last one known (0, facing +x, when none is), and Foxglove draws a
    body once a drawing gives its heading."""

    name: str
    x: float
    y: float
    theta: float | None
    half_m: float  # half the side of its square footprint


@dataclass(frozen=True)
class Row:
    """Some columns of a body's line in the viewer's table (`Scene.columns` names them)."""

    name: str
    values: tuple[tuple[str, str], ...]


@dataclass(frozen=True)
class Scan:
    """What a body's sensor hit, drawn as rays from the body when it is selected."""

    name: str
    points: tuple[Point, ...]


@dataclass(frozen=True)
class Plan:
    """A body's planned way; it may still hold the points already passed."""

    name: str
    points: tuple[Point, ...]


@dataclass(frozen=True)
class Start:
    """Where a body started."""

    name: str
    point: Point


@dataclass(frozen=True)
class Goal:
    """Where a body is going."""

    name: str
    point: Point


@dataclass(frozen=True)
class Collision:
    """An accident at `points`: `label` is its line in a list, `caption` the text beside it."""

    points: tuple[Point, ...]
    label: str
    caption: str


@dataclass(frozen=True)
class Order:
    """The order of the bodies (their colours and table rows follow it)."""

    names: tuple[str, ...]


Drawing = Grid | Body | Row | Scan | Plan | Start | Goal | Collision | Order
NAMED = (Body, Row, Scan, Plan, Start, Goal)  # the drawings that belong to one body


@runtime_checkable
class Scene(Protocol):
    """How one kind of fleet is drawn (module docstring)."""

    #: the table's columns after a body's name, in order
    columns: tuple[str, ...]

    def drawings(self, topic: str, type_name: str, data: Mapping[str, Any]) -> Sequence[Drawing]:
        """What one message on `topic` draws; `data` is the envelope's data as decoded
        (bytes stay bytes)."""
        ...

    def state_drawings(self, states: Mapping[str, Any],
                       params: Mapping[str, Mapping[str, Any]]) -> Sequence[Drawing]:
        """What the fleet looks like in a checker state: `states` maps every node to its
        state (JSON values, in the scenario's node order), `params` to its parameters."""
        ...
