"""A counterexample, step by step: what `twinfleet trace show` prints and what charts draw.

A trace file records each step's event, choices, changed states and digests,
not the messages a step sent. `walk` re-executes the trace on its system (as
`twinfleet replay` does, checking every digest) and reads each step's sent
events off its transition, so every step comes out whole: its time, the node
and handler that ran, the message it handled (kind, topic or service,
sender), the messages it sent (to whom, on what, due when), the states it
changed, its logs, the faults it injected (a message dropped or duplicated, a
node crashed: what the checker chose, so the reader sees why a message never
arrived), and at the end the property the trace violates.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any, final

from twinfleet.checker.growth import named_pairs
from twinfleet.checker.system import System
from twinfleet.checker.trace import NondeterminismError, recorded_step, replay_step, to_json_value
from twinfleet.checker.world import Event
from twinfleet.runtime.contract.kinds import EventKind


@final
@dataclass(frozen=True, slots=True)
class Sent:
    """One event a step added: a message to another node, or a timer of its own."""

    target: str
    handler: str
    kind: str
    name: str  # topic or service ("" for timers)
    due: int
    args: str


@final
@dataclass(frozen=True, slots=True)
class Shown:
    """One step of a counterexample (module docstring)."""

    index: int
    time: int
    node: str
    handler: str
    kind: str
    sender: str
    name: str  # the topic or service of the handled message ("" for timers and starts)
    args: str
    sent: tuple[Sent, ...]
    changed: Mapping[str, Any]
    logs: tuple[str, ...]
    failure: str | None
    faults: tuple[str, ...] = ()  # what the step's fault branches did: drops, duplicates, crashes


@final
@dataclass(frozen=True, slots=True)
class Walk:
    """A whole counterexample: its nodes, initial states, steps and violated property."""

    scenario: str
    nodes: tuple[str, ...]
    initial: Mapping[str, Any]
    steps: tuple[Shown, ...]
    property: str
    property_kind: str
    message: str
    cycle_start: int | None

    def to_json(self) -> dict[str, Any]:
        """The walk as plain JSON values."""
        return asdict(self)


def walk(system: System, trace: Mapping[str, Any]) -> Walk:
    """Re-execute `trace` on `system` and describe every step (module docstring).

    Raises:
        NondeterminismError: a step's world differs from the recorded one.
    """
    init = system.initial_world(tuple(trace["initial"]["choices"]))
    if init.world.digest.hex() != trace["initial"]["digest"]:
        raise NondeterminismError(0, "", "", "the initial world's digest differs")
    names = _names(system)
    world, steps = init.world, []
    for rec in trace["steps"]:
        t = replay_step(system, world, recorded_step(system, world, rec))
        if t.world.digest.hex() != rec["digest"]:
            raise NondeterminismError(rec["index"], rec["node"], rec["handler"],
                                      "the world's digest differs from the recorded one")
        steps.append(_shown(system, names, rec, t.event, tuple(t.sent)))
        world = t.world
    prop = trace["property"]
    initial = {n: to_json_value(system.decode(i, init.world.states[i]))
               for i, n in enumerate(system.names)}
    return Walk(str(trace.get("scenario") or ""), tuple(system.names), initial, tuple(steps),
                prop["name"], prop.get("kind", ""), str(trace.get("message", "")),
                trace.get("cycle_start"))


def _names(system: System) -> dict[tuple[int, str], str]:
    """The topic or service each (node, handler) receives on."""
    topology = system.runner.topology
    names = {(j, method): topic for topic, targets in topology.subscribers.items()
             for j, method, _ in targets}
    names.update((key, service) for key, service in topology.service_of.items())
    return names


def _shown(system: System, names: Mapping[tuple[int, str], str], rec: Mapping[str, Any],
           ev: Event, sent: tuple[Event, ...]) -> Shown:
    failure = rec.get("failure")
    return Shown(
        rec["index"], rec["time"], rec["node"], rec["handler"], rec["kind"], rec["sender"],
        names.get((ev.target, ev.method), "") if ev.kind.is_message else "", rec["args"],
        tuple(_sent(system, names, e) for e in sent), dict(rec.get("changed") or {}),
        tuple(_log_line(log) for log in rec.get("logs") or ()),
        None if failure is None else f"{failure.get('kind', '')}: {failure.get('message', '')}",
        tuple(str(f) for f in rec.get("faults") or ()))


def _sent(system: System, names: Mapping[tuple[int, str], str], e: Event) -> Sent:
    args = ", ".join(repr(a) for a in e.args)
    name = names.get((e.target, e.method), "") if e.kind is not EventKind.REPLY else ""
    return Sent(system.names[e.target], e.method, e.kind.value, name, e.due,
                args if len(args) <= 120 else args[:117] + "...")


def _log_line(log: Mapping[str, Any]) -> str:
    fields = ", ".join(f"{k}={v}" for k, v in log.items() if k != "event")
    return f"{log.get('event', '')} {fields}".strip()


def text_lines(shown: Walk) -> list[str]:
    """The walk for people: one block per step, a state change as the fields that changed,
    the violated property last."""
    out = [f"counterexample to {shown.property} ({shown.property_kind}), "
           f"{len(shown.steps)} steps; nodes: {', '.join(shown.nodes)}"]
    states = dict(shown.initial)
    if shown.cycle_start == 0:
        out.append("      (the cycle starts at the initial world)")
    for step in shown.steps:
        out += _step_lines(step, states)
        states.update(step.changed)
        if shown.cycle_start is not None and step.index == shown.cycle_start:
            out.append("      (the cycle starts after this step)")
    out.append(f"violated: {shown.property}: {shown.message}")
    return out


def _step_lines(step: Shown, states: Mapping[str, Any]) -> list[str]:
    source = (f" from {step.sender}" + (f" on {step.name}" if step.name else "")
              if EventKind(step.kind).is_message else "")
    lines = [f"{step.index:>4}  t={step.time} ms  {step.node}.{step.handler}  "
             f"[{step.kind}{source}]" + (f"  {step.args}" if step.args else "")]
    for s in step.sent:
        where = f" on {s.name}" if s.name else ""
        lines.append(f"        sends {s.kind}{where} to {s.target}.{s.handler} "
                     f"(due t={s.due} ms)" + (f": {s.args}" if s.args else ""))
    lines += [f"        FAULT {fault}" for fault in step.faults]
    for node, state in step.changed.items():
        lines.append(f"        state {node}: {_difference(states.get(node), state)}")
    lines += [f"        log {line}" for line in step.logs]
    if step.failure:
        lines.append(f"        FAILED {step.failure}")
    return lines


def _difference(before: Any, after: Any) -> str:
    """`field before -> after` for each field that changed (the whole state otherwise)."""
    if not (isinstance(before, Mapping) and isinstance(after, Mapping)):
        return f"{after}"
    changed = [line for k, v in after.items() if before.get(k) != v
               for line in _field_change(k, before.get(k), v)]
    return ", ".join(changed) or "(same fields, new object)"


def _field_change(key: str, before: Any, after: Any) -> list[str]:
    """`key before -> after`; a field holding attributes by name (an rclpy node's ``attrs``)
    as the attributes that changed, `key.name before -> after`, rather than all of them."""
    old, new = named_pairs(before), named_pairs(after)
    if old is None or new is None:
        return [f"{key} {_brief(before)!r} -> {_brief(after)!r}"]
    names = dict.fromkeys([*old, *new])
    return [f"{key}.{n} {_brief(old.get(n))!r} -> {_brief(new.get(n))!r}" for n in names
            if old.get(n) != new.get(n)]


_SNAPSHOT_HEX = re.compile(r"[0-9a-f]{33,}")  # bytes in a trace's JSON: a snapshot, a digest


class _Bytes(str):
    """Bytes a trace holds as hex, shown by their length (the trace file keeps them)."""

    def __repr__(self) -> str:
        return f"<{len(self) // 2} bytes>"


def _brief(value: Any) -> Any:
    """`value` with the long hex strings in it (an rclpy coroutine's arguments and start
    state, kept as snapshot bytes) shown as their length, not hundreds of digits."""
    if isinstance(value, str):
        return _Bytes(value) if _SNAPSHOT_HEX.fullmatch(value) else value
    if isinstance(value, list):
        return [_brief(v) for v in value]
    if isinstance(value, dict):
        return {k: _brief(v) for k, v in value.items()}
    return value


__all__ = ["Sent", "Shown", "Walk", "text_lines", "walk"]
