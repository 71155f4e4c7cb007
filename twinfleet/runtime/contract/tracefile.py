"""The trace file format (``twinfleet-trace/1``): reading, checking and writing the JSON.

A trace is the checker's counterexample: the scenario, the message semantics,
the violated property, the initial world and every step (see
`twinfleet.checker.trace`, which builds and replays them). The file format
lives here, in the contract layer, because the checker writes traces and the
viewer, the renderer and live replay read them.

Where the scenario is. A trace names its scenario file three ways: the
absolute path it was checked from (``scenario``), the path relative to the
trace file (``scenario_relative``, added by `write_trace`) and the file's
SHA-256 (``scenario_sha256``). `load_trace` looks beside the trace first, so a
project folder moved with its traces still replays, then at the absolute path;
it rewrites ``scenario`` to the file found and, when that file's digest is not
the recorded one, sets ``scenario_changed`` to a one-line note the commands
print (the scenario was edited since the trace was written, so the replay may
diverge). ``params`` lists the parameter overrides the trace was found with.
``node_code`` maps each node to the SHA-256 of its class's module source
(`code_sha256`), so that a replay of edited node code says so first
(`code_changes`) instead of only diverging.
"""

from __future__ import annotations

import hashlib
import inspect
import json
import os
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
    scenario = trace.get("scenario")
    if isinstance(scenario, str):  # found again beside the trace after a move (module doc)
        trace = {**trace, "scenario_relative": Path(os.path.relpath(
            Path(scenario).resolve(), out.parent.resolve())).as_posix()}
    out.write_text(json.dumps(trace, indent=1) + "\n")


def file_sha256(path: str | Path) -> str:
    """The SHA-256 of a file's bytes, in hex."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def code_sha256(cls: type) -> str | None:
    """The SHA-256 of the source file of the module that defines `cls` (None: built-in or
    defined where no file holds it): a node's code, as a trace records it."""
    try:
        source = inspect.getsourcefile(cls)
    except TypeError:
        return None
    return file_sha256(source) if source and Path(source).is_file() else None


def code_changes(trace: Mapping[str, Any], classes: Mapping[str, type]) -> list[str]:
    """One line per node (`classes`: node name → class, as loaded now) whose module's source
    differs from the one the trace recorded (``node_code``): a replay of changed code may
    diverge for that reason alone, so commands say it before anything else."""
    out = []
    for name, recorded in (trace.get("node_code") or {}).items():
        cls = classes.get(name)
        if cls is not None and recorded and code_sha256(cls) != recorded:
            out.append(f"node {name}'s code changed since the trace "
                       f"({inspect.getsourcefile(cls)})")
    return out


def _locate_scenario(trace: dict[str, Any], path: Path) -> None:
    """Point ``scenario`` at the file found (beside the trace first) and note a changed one."""
    relative = trace.get("scenario_relative")
    candidates = [path.resolve().parent / relative] if isinstance(relative, str) else []
    candidates.append(Path(trace["scenario"]))
    found = next((c for c in candidates if c.is_file()), None)
    if found is None:
        return  # loading the scenario says it is missing, naming the recorded path
    found = found.resolve()
    trace["scenario"] = str(found)
    recorded = trace.get("scenario_sha256")
    if isinstance(recorded, str) and file_sha256(found) != recorded:
        trace["scenario_changed"] = (f"{found}: the scenario changed since the trace was "
                                     "written (its SHA-256 differs); the replay may diverge")


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
    if isinstance(trace["scenario"], str):
        _locate_scenario(trace, Path(path))
    return trace


def _ints(value: Any) -> bool:
    return isinstance(value, list) and all(type(v) is int for v in value)


_TOP: dict[str, Any] = {
    "scenario": lambda v: v is None or isinstance(v, str),
    "params": lambda v: v is None or (isinstance(v, list) and all(isinstance(p, str) for p in v)),
    "semantics": lambda v: v in ("ros", "rebeca"),
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
