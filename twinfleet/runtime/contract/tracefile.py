"""The trace file format (``twinfleet-trace/1``): reading, checking and writing the JSON.

A trace is the checker's counterexample: the scenario, the message semantics,
the violated property, the initial world and every step (see
`twinfleet.checker.trace`, which builds and replays them). The file format
lives here, in the contract layer, because the checker writes traces and the
viewer, the renderer and live replay read them.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

TRACE_FORMAT = "twinfleet-trace/1"


class TraceError(ValueError):
    """A trace file is unreadable or not in a supported format."""


def write_trace(trace: Mapping[str, Any], path: str | Path) -> None:
    """Write a trace as indented JSON, creating parent directories."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(trace, indent=1) + "\n")


def load_trace(path: str | Path) -> dict[str, Any]:
    """Read a trace file, checking its format version."""
    try:
        trace = json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise TraceError(f"{path}: cannot read trace: {exc}") from None
    if not isinstance(trace, dict) or trace.get("format") != TRACE_FORMAT:
        raise TraceError(f"{path}: not a {TRACE_FORMAT} trace "
                         f"(format {trace.get('format') if isinstance(trace, dict) else None!r})")
    problem = trace_problem(trace)
    if problem:
        raise TraceError(f"{path}: malformed trace: {problem}")
    return trace


def _ints(value: Any) -> bool:
    return isinstance(value, list) and all(type(v) is int for v in value)


_TOP: dict[str, Any] = {
    "scenario": lambda v: isinstance(v, str),
    "semantics": lambda v: v in ("ros", "rebeca"),
    "profile": lambda v: v is None or isinstance(v, str),
    "latency": lambda v: v is None or (_ints(v) and len(v) == 2),
    "topic_latency": lambda v: v is None or (isinstance(v, list) and all(
        isinstance(e, list) and len(e) == 2 and isinstance(e[0], str) and _ints(e[1])
        and len(e[1]) == 2 for e in v)),
    "global_priority": lambda v: v is None or isinstance(v, bool),
    "property": lambda v: isinstance(v, dict) and isinstance(v.get("name"), str)
    and isinstance(v.get("kind"), str),
    "cycle_start": lambda v: v is None or type(v) is int,
    "initial": lambda v: isinstance(v, dict) and _ints(v.get("choices"))
    and isinstance(v.get("digest"), str) and isinstance(v.get("states", {}), dict),
    "steps": lambda v: isinstance(v, list),
}
_STEP: dict[str, Any] = {
    "index": lambda v: type(v) is int, "time": lambda v: type(v) is int,
    "node": lambda v: isinstance(v, str), "handler": lambda v: isinstance(v, str),
    "event": lambda v: type(v) is int, "choices": _ints, "digest": lambda v: isinstance(v, str),
    "changed": lambda v: isinstance(v, dict),
}


def trace_problem(trace: Mapping[str, Any]) -> str | None:
    """What is wrong with a decoded trace's structure, or None if it is well formed."""
    for key, ok in _TOP.items():
        if not ok(trace.get(key)):
            return f"key {key!r} is missing or has the wrong type ({trace.get(key)!r:.60})"
    for k, step in enumerate(trace["steps"]):
        if not isinstance(step, dict):
            return f"steps[{k}] is not a mapping"
        for key, ok in _STEP.items():
            if not ok(step.get(key)):
                return f"steps[{k}].{key} is missing or has the wrong type ({step.get(key)!r:.60})"
    return None
