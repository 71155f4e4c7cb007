"""Counterexample traces: versioned JSON files, and deterministic replay.

A trace (``"format": "twinfleet-trace/1"``) names the scenario, the message
semantics and the violated property, then lists the initial world and every
step: logical time, node, handler, event kind, sender, a summary of the
arguments, the `ctx.choose` indices (and how many options each choice point
had), the fault branches taken (`faults`), the digest of the resulting world
and the decoded state of the node that changed. A crash fault is a step of
kind "crash" whose `event` is the crashed node's index; a KEEP_LAST drop is a step
of kind "drop" whose `event` is the dropped delivery's index. A lasso trace also
has `cycle_start`: the index of the world (0 = initial) that the last step
returns to.

Kinds are `EventKind` values ("delivery", "request", "reply", "timeout",
"timer", "periodic", "crash"); a step of kind "crash" is a `Crash` action,
"drop" a `Drop` of pending event `event`, any other a `RunEvent` of it.

`replay(system, trace)` re-runs the steps from the recorded choices (with
`System.step`, the one step function), checks
every world's digest against the file and confirms that the recorded property
is violated at the end, raising `NondeterminismError` at the first divergence.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, final

import numpy as np

from twinfleet.checker.choices import PrefixChooser
from twinfleet.checker.outcome import Counterexample
from twinfleet.checker.properties import PropertySet, PropertyViolation
from twinfleet.checker.system import System
from twinfleet.checker.transition import Action, Crash, Drop, RunEvent, Step, Transition
from twinfleet.checker.world import ENVIRONMENT, World
from twinfleet.runtime.contract.kinds import EventKind
from twinfleet.runtime.contract.tracefile import TRACE_FORMAT, code_sha256


class NondeterminismError(RuntimeError):
    """Replaying a trace produced a different world than the one recorded.

    Attributes:
        step: the 1-based step that diverged (0 = the initial world).
        node: the node whose handler ran in that step ("" for the initial world).
        handler: that handler's method name.
    """

    def __init__(self, step: int, node: str, handler: str, detail: str) -> None:
        where = f"step {step} ({node}.{handler})" if node else "the initial world"
        super().__init__(
            f"replay diverged at {where}: {detail}. Likely causes: the handler reads the wall "
            "clock or `time`, uses `random`, iterates a set of strings (order depends on "
            "PYTHONHASHSEED), keeps state outside self.state (rerun `check --debug-state`), "
            "or the node code or scenario changed since the trace was written.")
        self.step = step
        self.node = node
        self.handler = handler


def to_json_value(value: Any) -> Any:
    """A JSON-ready copy of a state or message: dataclasses become dicts, tuples lists."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: to_json_value(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, dict):
        return {str(k): to_json_value(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [to_json_value(v) for v in value]
    if isinstance(value, set | frozenset):
        return sorted((to_json_value(v) for v in value), key=repr)
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, bytes):
        return value.hex()
    if value is None or isinstance(value, bool | int | float | str):
        return value
    return repr(value)


def _summary(args: Sequence[Any]) -> str:
    text = ", ".join(repr(a) for a in args)
    return text if len(text) <= 200 else text[:197] + "..."


def build_trace(system: System, violation: PropertyViolation, path: Counterexample, *,
                scenario_path: str | None, search: str = "bfs",
                scenario_sha256: str | None = None,
                params: Sequence[str] = ()) -> dict[str, Any]:
    """Re-execute the counterexample `path` and describe every step as a JSON-ready trace
    (with the scenario's digest and the parameter overrides, so that `replay` finds and
    loads the same configuration)."""
    init = system.initial_world(path.initial)
    world = init.world
    trace: dict[str, Any] = {
        "format": TRACE_FORMAT,
        "scenario": scenario_path,
        "scenario_sha256": scenario_sha256,
        "params": list(params),
        "semantics": system.semantics.value,
        "latency": list(system.rules.latency) if system.rules.latency else None,
        "topic_latency": [[name, list(span)] for name, span in system.topic_latency] or None,
        "global_priority": system.rules.global_priority,
        "debug_state": system.debug_state,
        "check_determinism": system.check_determinism,
        "node_code": {cfg.name: code_sha256(cfg.cls) for cfg in system.scenario.nodes},
        "search": search,
        "property": {"name": violation.property, "kind": violation.kind},
        "shape": violation.shape,
        "message": violation.message,
        "cycle_start": path.cycle_start,
        "initial": {"choices": list(path.initial), "digest": world.digest.hex(),
                    "next_time": world.next_time,
                    "states": {n: to_json_value(s) for n, s in system.states_of(world).items()},
                    "failure": _failure(init) if not path.steps else None},
        "steps": [],
    }
    for k, step in enumerate(path.steps, start=1):
        t = replay_step(system, world, step)
        trace["steps"].append(_describe(system, k, world, t))
        world = t.world
    return trace


def replay_step(system: System, world: World, step: Step) -> Transition:
    """Take a recorded step again: its action with its recorded choices."""
    assert step.action is not None, "an initial world is rebuilt with System.initial_world"
    return system.step(world, step.action, PrefixChooser(step.choices))


def _action_index(action: Action | None) -> int:
    """What a trace step records as `event`: the event index, or the crashed node."""
    match action:
        case RunEvent(index=index):
            return index
        case Crash(node=node):
            return node
        case Drop(index=index):
            return index
    raise ValueError(f"not a step's action: {action!r}")


def _describe(system: System, k: int, before: World, t: Transition) -> dict[str, Any]:
    ev = t.event
    after = t.world
    changed = {system.names[i]: to_json_value(system.decode(i, after.states[i]))
               for i in range(len(system.names)) if after.states[i] is not before.states[i]}
    return {
        "index": k, "time": ev.due, "node": system.names[ev.target], "handler": ev.method,
        "kind": ev.kind.value,
        "sender": "environment" if ev.sender == ENVIRONMENT else system.names[ev.sender],
        "event": _action_index(t.step.action), "args": _summary(ev.args),
        "choices": list(t.step.choices), "options": list(t.step.options),
        "digest": after.digest.hex(), "next_time": after.next_time,
        "pending": len(after.events), "changed": changed, "faults": list(t.faults),
        "logs": [{"event": log.event, **{k2: to_json_value(v) for k2, v in log.fields}}
                 for log in t.logs],
        "failure": _failure(t),
    }


def _failure(t: Transition) -> dict[str, str] | None:
    f = t.failure
    if f is None:
        return None
    return {"kind": f.kind.value, "node": f.node, "handler": f.handler, "message": f.message,
            "traceback": f.traceback}


@final
@dataclass(frozen=True, slots=True)
class ReplayResult:
    """What a replay found: whether the recorded violation happened again."""

    confirmed: bool
    property: str
    message: str
    steps: int


def replay(system: System, trace: Mapping[str, Any],
           properties: PropertySet | None = None) -> ReplayResult:
    """Re-execute `trace` on `system`, checking digests, and confirm its violation.

    Raises:
        NondeterminismError: a step's world differs from the recorded one.
        TraceError: the trace does not fit this system (unknown event index...).
    """
    props = properties or PropertySet.from_scenario(system.scenario)
    init = system.initial_world(tuple(trace["initial"]["choices"]))
    if init.world.digest.hex() != trace["initial"]["digest"]:
        raise NondeterminismError(0, "", "", "the initial world's digest differs")
    worlds, last = [init.world], init
    for rec in trace["steps"]:
        last = _replay_step(system, worlds[-1], rec)
        worlds.append(last.world)
    confirmed, message = _confirm(system, props, trace, worlds, last)
    return ReplayResult(confirmed, trace["property"]["name"], message, len(trace["steps"]))


def recorded_step(system: System, world: World, rec: Mapping[str, Any]) -> Step:
    """The step a trace's step record names in `world`, checked to fit it.

    Raises:
        NondeterminismError: no such pending event (or crash) in `world`.
    """
    k, index = rec["index"], rec["event"]
    choices, options = tuple(rec["choices"]), tuple(rec["options"])
    crash = system.settings.crash
    if rec.get("kind") == EventKind.CRASH:
        if crash is None or index not in crash.nodes:
            raise NondeterminismError(k, rec["node"], "crash", "the scenario does not let this "
                                      "node crash (check.faults.crash)")
        return Step(Crash(index), choices, options)
    if rec.get("kind") == EventKind.DROP:
        if index not in system.rules.droppable(world.events):
            raise NondeterminismError(k, rec["node"], rec["handler"], f"pending event {index} "
                                      "cannot be dropped here (KEEP_LAST, Rule 6)")
        return Step(Drop(index), choices, options)
    if not 0 <= index < len(world.events):
        raise NondeterminismError(k, rec["node"], rec["handler"],
                                  f"event {index} does not exist ({len(world.events)} pending)")
    ev = world.events[index]
    if system.names[ev.target] != rec["node"] or ev.method != rec["handler"]:
        raise NondeterminismError(k, rec["node"], rec["handler"],
                                  f"pending event {index} is {system.names[ev.target]}.{ev.method}")
    return Step(RunEvent(index), choices, options)


def _replay_step(system: System, world: World, rec: Mapping[str, Any]) -> Transition:
    t = replay_step(system, world, recorded_step(system, world, rec))
    return _check_digest(t, rec["index"], rec)


def _check_digest(t: Transition, k: int, rec: Mapping[str, Any]) -> Transition:
    if t.world.digest.hex() != rec["digest"]:
        raise NondeterminismError(k, rec["node"], rec["handler"],
                                  f"world digest {t.world.digest.hex()} != recorded {rec['digest']}")
    return t


def _confirm(system: System, props: PropertySet, trace: Mapping[str, Any], worlds: list[World],
             last: Transition) -> tuple[bool, str]:
    name, kind = trace["property"]["name"], trace["property"]["kind"]
    if last.failure is not None:
        failed = props.check_failure(last.failure)
        return failed.property == name, failed.message
    if kind == "eventually":
        return _confirm_eventually(system, props, trace, worlds, name)
    violation = props.check_world(system, worlds[-1])
    if violation is None:
        return False, "the final world violates no property"
    return violation.property == name, violation.message


def _confirm_eventually(system: System, props: PropertySet, trace: Mapping[str, Any],
                        worlds: list[World], name: str) -> tuple[bool, str]:
    prop = next((p for p in props.eventually if p.name == name), None)
    if prop is None or prop.expr is None:
        return False, f"the scenario has no eventually property {name!r}"
    if any(prop.expr.holds(system, w.states, w.now) for w in worlds):
        return False, f"{prop.expr.source!r} holds somewhere on the replayed path"
    start = trace.get("cycle_start")
    if start is None:
        ok = worlds[-1].terminal
        return ok, "path ends with nothing pending" if ok else "path does not end"
    ok = worlds[-1].digest == worlds[start].digest
    return ok, (f"cycle back to world {start} confirmed" if ok else "the cycle does not close")
