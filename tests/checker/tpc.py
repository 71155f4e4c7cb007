"""The two-phase commit of tests/data/tpc in a smaller shape, written as a scenario file: a
coordinator and two participants, one prepare and no retry (the user's protocol of issue 37).

A participant that has voted yes gives up (aborts on its own) after `decision_timeout_ms`
without a decision; the coordinator aborts after `vote_timeout_ms` without every vote.
`atomic` breaks when one participant aborts on its own while the coordinator commits.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from tests.data.tpc.tpc_nodes import ABORT, COMMIT

NODES = "tests.data.tpc.tpc_nodes"
ATOMIC = f"not (coord.decided == {COMMIT} and (p1.outcome == {ABORT} or p2.outcome == {ABORT}))"


def tpc_scenario(folder: Path, name: str = "tpc", *, latency: tuple[int, int] | None = (0, 2),
                 **params: Any) -> Path:
    """Write the two-phase commit of three nodes as a scenario file in `folder` (`params`:
    its common `params:`, e.g. decision_timeout_ms=1)."""
    doc: dict[str, Any] = {
        "name": name, "semantics": "ros",
        "params": {"participants": 2, "retries": 0, "vote_timeout_ms": 12,
                   "decision_timeout_ms": 8, **params},
        "nodes": [{"name": "coord", "class": f"{NODES}:Coordinator"},
                  {"name": "p1", "class": f"{NODES}:Participant"},
                  {"name": "p2", "class": f"{NODES}:Participant"}],
        "properties": [{"name": "atomic", "kind": "invariant", "expr": ATOMIC}],
        "live": {"wall_timeout_s": 1}}
    if latency is not None:
        doc["check"] = {"latency": list(latency)}
    path = folder / f"{name}.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path
