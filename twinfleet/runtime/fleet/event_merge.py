"""The fleet's event log: one part per node while it runs, one merged file after.

With ``record_events=PATH`` (`launcher.run_fleet`) every node logs each event it dispatches
(`runtime.core.eventlog.EventLog`) into ``PATH.parts/<node>.jsonl``, flushed per line;
after shutdown the launcher merges the parts into PATH: a ``fleet`` header line, the node
headers, then every event in dispatch-time order (each node's own order kept, a respawn as
a ``crash`` record: `eventlog.with_restarts`), and removes the parts.
"""

from __future__ import annotations

import contextlib
import heapq
import json
import shutil
from pathlib import Path
from typing import TYPE_CHECKING

from twinfleet.runtime.core.eventlog import EVENTS_FORMAT, with_restarts

if TYPE_CHECKING:
    from twinfleet.runtime.fleet.live_fleet import Fleet


def fresh_parts_dir(path: str) -> Path:
    """An empty ``<path>.parts`` directory for the nodes' logs (a previous run's removed)."""
    parts = Path(f"{path}.parts")
    if parts.exists():
        shutil.rmtree(parts)
    parts.mkdir(parents=True)
    return parts


def merge_events(parts: Path, path: str, fleet: Fleet) -> int:
    """Merge the per-node event logs in `parts` into `path` (module docstring); return how
    many events there are."""
    headers, streams, restarts = [], [], {}
    for cfg in fleet.scenario.nodes:
        part = parts / f"{cfg.name}.jsonl"
        lines = part.read_text().splitlines() if part.exists() else []
        records = []
        for line in lines:
            with contextlib.suppress(json.JSONDecodeError):  # a torn last line
                records.append(json.loads(line))
        headers += [r for r in records if r.get("kind") == "header"][:1]
        events, restarted = with_restarts(records)
        if restarted:
            restarts[cfg.name] = restarted
        streams.append(events)
    with open(path, "w", encoding="utf-8") as f:
        f.write(json.dumps({"format": EVENTS_FORMAT, "kind": "fleet",
                            "scenario": str(fleet.scenario.path), "fleet": fleet.scenario.fleet,
                            "seed": fleet.seed, "time_scale": fleet.time_scale,
                            "epoch_ns": fleet.epoch_ns, "node_args": list(fleet.node_args),
                            "nodes": [c.name for c in fleet.scenario.nodes],
                            "restarts": restarts}) + "\n")
        for record in [*headers, *heapq.merge(*streams, key=lambda r: r["t"])]:
            f.write(json.dumps(record, separators=(",", ":")) + "\n")
    shutil.rmtree(parts, ignore_errors=True)
    return sum(len(s) for s in streams)


def merge_logged(parts: Path, path: str, fleet: Fleet) -> None:
    """`merge_events`, and a launcher line saying what came of it."""
    try:
        count = merge_events(parts, path, fleet)
        fleet.log(f"{count} events written to {path}; check them with: "
                  f"twinfleet validate {path} {fleet.scenario.path}")
    except OSError as exc:  # the parts stay; `validate` reads them too
        fleet.log(f"could not merge the event logs in {parts}: {exc}")
