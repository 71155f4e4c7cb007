"""The live run summary of the robot system, computed from the messages a fleet publishes.

The robots keep no statistics in their state (it would split checker states),
so the report counts from what it hears: hops and distance from `/poses`,
waits, back-offs and arrival from each robot's `status`, and collisions from
`/collisions`. The launcher feeds it every message of `topics()` and prints
`render()` at the end. The run's result is not the report's: it is the live
verdict on the scenario's properties (`runtime.fleet.live_verdict`), where a
collision is the `no_collision` invariant (``map_server.collisions == 0``) and
an unarrived robot the `all_arrive` eventually property; `passed()` (no
collision, every robot arrived) is kept for the run record.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from twinfleet.nodes.mapfile import load_map
from twinfleet.nodes.msgs import Collision, RobotPose, RobotStatus

CELL_M = 0.255


@dataclass
class RobotRecord:
    """What one robot did in a live run."""

    arrived: bool = False
    arrival_ms: int | None = None  # since the robot's own start (its first status)
    start_ms: int | None = None
    hops: int = 0
    distance_m: float = 0.0
    waits: int = 0
    backoffs: int = 0
    failures: int = 0
    mode: str = "unknown"
    last_cell: tuple[int, int] | None = None


@dataclass
class FleetReport:
    """Collects one run's robot records and collisions."""

    robots: tuple[str, ...]
    cell_m: float = CELL_M
    records: dict[str, RobotRecord] = field(default_factory=dict)
    collisions: list[Collision] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.records = {r: RobotRecord() for r in self.robots}

    def topics(self) -> list[str]:
        """The fully qualified topics the report needs."""
        return ["/poses", "/collisions", *(f"/{r}/status" for r in self.robots)]

    def on_message(self, topic: str, msg: Any) -> None:
        """Account for one received message."""
        if isinstance(msg, Collision):
            self.collisions.append(msg)
        elif isinstance(msg, RobotPose) and msg.robot in self.records:
            self._on_pose(self.records[msg.robot], (msg.cell[0], msg.cell[1]))
        elif isinstance(msg, RobotStatus) and msg.robot in self.records:
            self._on_status(self.records[msg.robot], msg)

    def _on_pose(self, rec: RobotRecord, cell: tuple[int, int]) -> None:
        if rec.last_cell is not None and cell != rec.last_cell:
            rec.hops += 1
            rec.distance_m += self.cell_m * math.dist(cell, rec.last_cell)
        rec.last_cell = cell

    @staticmethod
    def _on_status(rec: RobotRecord, msg: RobotStatus) -> None:
        if rec.start_ms is None:
            # Fleet time counts from the launcher's epoch, before the node processes
            # started; a robot's first status marks its own time zero.
            rec.start_ms = msg.time_ms
        if msg.mode != rec.mode:
            rec.waits += msg.mode == "waiting"
            rec.backoffs += msg.mode == "backing_off"
        rec.mode = msg.mode
        rec.failures = msg.failures
        if msg.mode == "arrived" and not rec.arrived:
            rec.arrived, rec.arrival_ms = True, msg.time_ms - rec.start_ms

    def finished(self) -> bool:
        """True when every robot has arrived or is stuck for good: nothing more will happen.

        This ends live runs of the `rebeca` profile too, whose robots (like the
        paper's model) never tell the map server that they are done.
        """
        return all(r.arrived or r.mode == "stuck" for r in self.records.values())

    def passed(self) -> bool:
        """True when every robot arrived and no collision was seen."""
        return not self.collisions and all(r.arrived for r in self.records.values())

    def render(self) -> str:
        """A table per robot and the list of collisions."""
        lines = [f"{'robot':<6} {'arrived':<8} {'time s':>7} {'hops':>5} {'dist m':>7} "
                 f"{'waits':>5} {'backoffs':>8} {'failures':>8}  state"]
        for name, r in self.records.items():
            t = f"{r.arrival_ms / 1000:.2f}" if r.arrival_ms is not None else "-"
            lines.append(f"{name:<6} {'yes' if r.arrived else 'no':<8} {t:>7} {r.hops:>5} "
                         f"{r.distance_m:>7.2f} {r.waits:>5} {r.backoffs:>8} {r.failures:>8}  {r.mode}")
        if self.collisions:
            lines.append(f"collisions: {len(self.collisions)}")
            lines += [f"  t={c.time_ms / 1000:.2f}s {c.robot_a} {tuple(c.cell_a)} <-> "
                      f"{c.robot_b} {tuple(c.cell_b)}" for c in self.collisions[:20]]
            if len(self.collisions) > 20:
                lines.append(f"  ... {len(self.collisions) - 20} more")
        else:
            lines.append("collisions: none")
        return "\n".join(lines)


def report_for(scenario: Any) -> FleetReport | None:
    """A report for a scenario that has a map server (None for other fleets)."""
    for cfg in scenario.nodes:
        if hasattr(cfg.params, "robots") and hasattr(cfg.params, "map"):
            return FleetReport(tuple(cfg.params.robots), load_map(cfg.params.map).resolution)
    return None
