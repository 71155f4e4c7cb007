"""The run record of a live run: JSON lines, flushed one by one, so a crash keeps what was written.

`run_fleet(..., LaunchOptions(run_record=PATH))` writes one JSON object per line::

    {"event": "start", "t": 0.0, "wall": 1718000000.1, "scenario": "launch/demo.yaml",
     "name": "demo", "fleet": "demo", "seed": 1, "time_scale": 1.0, "timeout_s": 30,
     "endpoint": "tcp/127.0.0.1:40123", "versions": {...}, "nodes": [...]}
    {"event": "node_exit", "t": 2.4, "node": "r1", "code": -9, "last_lines": [...]}
    {"event": "respawn", "t": 2.9, "node": "r1", "restart": 1}
    {"event": "end", "t": 6.0, "reason": "timeout after 6 s"}
    {"event": "node_stats", "t": 6.0, "stats": {"r1": {"received": 12, ...}, ...}}
    {"event": "summary", "t": 6.3, "ok": true, "passed": true,
     "verdict": {"status": "holds", "summary": "...", "details": [], "property": null,
                 "exit_code": 0}, "exit_codes": {...},
     "failed": [], "restarts": {"r1": 1}, "duration_s": 6.3, "last_messages": {...},
     "report": {"passed": true, "text": "...", "data": {...}}}

``t`` is seconds since the record was opened, ``wall`` the Unix time. Every
line is complete JSON on its own; readers skip a torn last line. The file is
appended to, so the runs of ``launch --runs N`` share one file, each beginning
with its ``start`` event.
"""

from __future__ import annotations

import dataclasses
import enum
import json
import platform
import time
from importlib import metadata
from pathlib import Path
from typing import Any, TextIO, final


def versions() -> dict[str, str]:
    """Versions of Python and of the distributions a run depends on."""
    found = {"python": platform.python_version()}
    for dist in ("twinfleet", "eclipse-zenoh", "msgpack", "numpy", "pyyaml"):
        try:
            found[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            found[dist] = "not installed"
    return found


def plain(value: Any) -> Any:
    """A JSON-ready copy of `value`: dataclasses become maps, tuples lists, bytes hex, the rest repr."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple | set | frozenset):
        return [plain(v) for v in value]
    if isinstance(value, bytes):
        return value.hex()
    if isinstance(value, enum.Enum):
        return value.value
    if value is None or isinstance(value, bool | int | float | str):
        return value
    return repr(value)


@final
class RunRecord:
    """Appends events to a JSON-lines file and flushes after each one.

    Args:
        path: the file to append to (created if missing).
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._out: TextIO | None = self.path.open("a", encoding="utf-8")
        self._started = time.monotonic()

    def write(self, event: str, **fields: Any) -> None:
        """One line: the event, the time since the start, and `fields` made JSON-ready."""
        if self._out is None:
            return
        line = {"event": event, "t": round(time.monotonic() - self._started, 3),
                "wall": round(time.time(), 3), **{k: plain(v) for k, v in fields.items()}}
        self._out.write(json.dumps(line, ensure_ascii=False) + "\n")
        self._out.flush()

    def close(self) -> None:
        """Close the file; later writes are ignored."""
        if self._out is not None:
            self._out.close()
            self._out = None


def read_run_record(path: str | Path) -> list[dict[str, Any]]:
    """The events of a run record, skipping a torn last line (the writer was killed mid-line)."""
    events = []
    for line in Path(path).read_text(encoding="utf-8").splitlines():
        try:
            events.append(json.loads(line))
        except json.JSONDecodeError:
            continue
    return events
