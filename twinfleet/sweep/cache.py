"""Each finished point on disk, so a stopped sweep resumes where it stopped.

A point's file is ``OUT/points/KEY.json``; KEY digests the scenario (its file and the
source files of its node classes: a changed node is a different model), the search
settings that change an answer (order, reduction, limits, contract checks) and the point.
A file is written whole and renamed into place, so a sweep killed mid-write leaves no
half record; a record that cannot be read is run again.
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
from pathlib import Path
from typing import Any

from twinfleet.sweep.grid import Point
from twinfleet.sweep.point import PointResult, SweepSettings


def scenario_digest(path: str) -> str:
    """sha256 of a scenario file and of the modules its node classes come from."""
    from twinfleet.runtime.scenario.spec import load_scenario

    digest = hashlib.sha256(Path(path).read_bytes())
    modules = sorted({cfg.cls.__module__ for cfg in load_scenario(path).nodes})
    for name in modules:
        source = getattr(sys.modules.get(name), "__file__", None)
        digest.update(name.encode())
        if source:
            digest.update(Path(source).read_bytes())
    return digest.hexdigest()


def point_key(scenario: str, settings: SweepSettings, point: Point) -> str:
    """The cache key of one point (32 hex digits)."""
    record: dict[str, Any] = {
        "scenario": scenario, "point": [[n, v] for n, v in point],
        "fixed": [[n, v] for n, v in settings.fixed], **settings.check.fields()}
    text = json.dumps(record, sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()[:32]


class PointCache:
    """The finished points of a sweep under one output folder."""

    def __init__(self, out: str | Path) -> None:
        self.folder = Path(out) / "points"
        self.folder.mkdir(parents=True, exist_ok=True)

    def get(self, key: str) -> PointResult | None:
        """The stored result of point `key`, or None (not run, or unreadable)."""
        path = self.folder / f"{key}.json"
        try:
            return PointResult.from_json(json.loads(path.read_text()))
        except (OSError, ValueError, KeyError, TypeError):
            return None

    def put(self, key: str, result: PointResult) -> None:
        """Store a finished point (atomically: a temporary file renamed into place)."""
        path = self.folder / f"{key}.json"
        partial = path.with_suffix(f".{os.getpid()}.tmp")
        partial.write_text(json.dumps(result.to_json(), indent=1))
        partial.replace(path)

    def clear(self) -> None:
        """Forget every finished point (``--rerun``)."""
        for path in self.folder.glob("*.json"):
            path.unlink()
