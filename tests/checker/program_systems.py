"""Hypothesis strategies for small random node systems (scenario mappings of program nodes).

`systems()` draws a whole scenario as plain data: 2-4 `ProgramNode`s (some
periodic) whose handlers publish to random topics of random priority, set
timers, call services (with timeouts; sometimes a service nobody serves),
branch with `ctx.choose`, and sometimes echo a message on without spending its
time-to-live (zero-time cycles, when echoes meet); optional `latency`, `faults` (drop, duplicate,
crash), `deadline_ms` and `queue_bound`; either semantics, with node
priorities and `global_priority` under `rebeca`; and 1-3 random properties of
every kind (invariant, eventually, within, deadlock with or without a goal,
quiescence, no_failure). `write_scenario` turns one into a YAML file.

Everything is bounded so that most systems have a few hundred states at most
(see `tests/checker/test_reduction_differential.py` for the measured sizes):
messages carry a time-to-live of at most 2, a handler has at most two
actions, and nesting (`if`, `choose`) is one level deep.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import yaml
from hypothesis import strategies as st

from tests.checker.program_nodes import BUS, INPUT_TOPICS, MOD, REGISTERS, SERVICE, TIMER_SLOTS

CLASSES = {"plain": "tests.checker.program_nodes:ProgramNode",
           "shallow": "tests.checker.program_nodes:ShallowProgramNode",
           "periodic": "tests.checker.program_nodes:PeriodicProgramNode",
           "commuting": "tests.checker.program_nodes:CommutingProgramNode"}
HANDLERS_OF = {"plain": ("start", "in0", "in1", "in2", "bus", "svc", "t0", "t1", "reply"),
               "shallow": ("start", "in0", "in1", "in2", "bus", "svc", "t0", "t1", "reply"),
               "periodic": ("start", "in0", "in1", "in2", "bus", "svc", "t0", "t1", "reply",
                            "tick"),
               "commuting": ("start", "in0", "in1", "in2", "bus", "svc", "t0", "t1", "reply")}
NO_SERVER = "/nobody/svc"  # a call to it ends in CallError("no server") after its timeout
DELAYS = (0, 0, 5, 10)  # ctx.after delays in ms (0 twice: simultaneous events matter most)
TIMEOUTS = (5, 20)
PERIODS = (10, 20, 30)
TTLS = (1, 2, 2, 3)  # hops a chain of events may take


def names_of(count: int) -> list[str]:
    """Node names n1..n<count>."""
    return [f"n{i + 1}" for i in range(count)]


def topics_of(names: Sequence[str]) -> list[str]:
    """Every topic some program node subscribes to (all of them have a subscriber)."""
    return [f"/{n}/{t}" for n in names for t in INPUT_TOPICS] + [BUS]


def services_of(names: Sequence[str]) -> list[str]:
    """Every served service name."""
    return [f"/{n}/{SERVICE}" for n in names]


@functools.cache  # strategies are immutable: built once per set of names, not per draw
def _send(names: tuple[str, ...]) -> st.SearchStrategy[list[Any]]:
    """An action that makes something happen later: a publish, a timer or a call."""
    return st.one_of(
        st.tuples(st.just("pub"), st.sampled_from(topics_of(names))),
        st.tuples(st.just("pub"), st.sampled_from(topics_of(names))),
        st.tuples(st.just("after"), st.sampled_from(DELAYS), st.integers(0, TIMER_SLOTS - 1)),
        st.tuples(st.just("call"), st.sampled_from([*services_of(names), NO_SERVER]),
                  st.sampled_from(TIMEOUTS)),
    ).map(list)


def _echo(name: str, names: Sequence[str], handler: str) -> st.SearchStrategy[list[Any]]:
    """A publish that keeps its ttl, to the same input of some node (itself included): echoes
    on one input name chain up and often close a zero-time cycle. One subscriber only (on
    /bus echoes would multiply)."""
    return st.builds(lambda n: ["echo", f"/{n}/{handler}"], st.sampled_from([name, *names]))


@functools.cache
def _leaf(names: tuple[str, ...]) -> st.SearchStrategy[list[Any]]:
    reg = st.integers(0, REGISTERS - 1)
    local = st.one_of(
        st.tuples(st.just("add"), reg, st.integers(1, MOD - 1)),
        st.tuples(st.just("take"), reg),
        st.tuples(st.just("add"), reg, st.integers(1, MOD - 1)),
        st.tuples(st.just("fail"), reg, st.integers(1, MOD - 1)),
        st.tuples(st.just("max"), reg, st.integers(1, MOD - 1)),
    ).map(list)
    return st.one_of(_send(names), local)


@functools.cache
def _commuting(names: tuple[str, ...]) -> st.SearchStrategy[list[Any]]:
    """An action of a handler declared commutes=True: an add, a max or a send, so whether two
    of its messages commute does not depend on the node's state (the pair check is exact)."""
    reg = st.integers(0, REGISTERS - 1)
    return st.one_of(_send(names), st.tuples(st.sampled_from(["add", "max"]), reg,
                                             st.integers(1, MOD - 1)).map(list))


@functools.cache
def _action(names: tuple[str, ...]) -> st.SearchStrategy[list[Any]]:
    leaf = _leaf(names)
    short = st.lists(leaf, max_size=1)
    nested = st.one_of(
        st.tuples(st.just("if"), st.integers(0, REGISTERS - 1), st.integers(0, MOD - 1),
                  short, short).map(list),
        st.tuples(st.just("choose"), st.lists(short, min_size=2, max_size=2)).map(list),
    )
    return st.one_of(leaf, leaf, leaf, nested)  # nesting one time in four


_KINDS = st.sampled_from(["plain", "plain", "shallow", "periodic", "commuting"])


@functools.cache
def _lists(strategy: st.SearchStrategy[Any], min_size: int, max_size: int,
           ) -> st.SearchStrategy[list[Any]]:
    return st.lists(strategy, min_size=min_size, max_size=max_size)


@functools.cache
def _handlers(kind: str) -> st.SearchStrategy[list[str]]:
    return st.lists(st.sampled_from(HANDLERS_OF[kind]), min_size=2, max_size=6, unique=True)


@st.composite
def _node(draw: st.DrawFn, name: str, names: tuple[str, ...], semantics: str,
          bus_start: bool = False, kind: str | None = None) -> dict[str, Any]:
    kind = kind or draw(_KINDS)
    action = _action(names)
    program: dict[str, list[Any]] = {}
    if bus_start:  # every node publishes on /bus at t=0: simultaneous messages to each node
        program["start"] = [["pub", BUS]]
    elif name == names[0] or draw(st.booleans()):  # n1 starts something: not one state
        program["start"] = [draw(_send(names)), *draw(_lists(action, 0, 1))]
    for h in draw(_handlers(kind)):
        program.setdefault(h, draw(_lists(action, 1, 2)))
    if kind == "commuting":  # its /bus handler is declared commutes=True
        program["bus"] = draw(_lists(_commuting(names), 1, 2))
    inputs = [h for h in program if h in INPUT_TOPICS]
    if inputs and _sometimes(draw, 3):  # one input handler only echoes
        echoing = draw(st.sampled_from(inputs))
        program[echoing] = [draw(_echo(name, names, echoing))]
    params: dict[str, Any] = {"program": json.dumps(program, separators=(",", ":")),
                              "ttl": draw(st.sampled_from(TTLS))}
    if kind == "periodic":
        params["period_ms"] = draw(st.sampled_from(PERIODS))
    entry: dict[str, Any] = {"name": name, "class": CLASSES[kind], "namespace": f"/{name}",
                             "params": params}
    if semantics == "rebeca" and draw(st.booleans()):
        entry["priority"] = draw(st.integers(1, 3))
    return entry


@functools.cache
def _atom(names: tuple[str, ...], ops: tuple[str, ...]) -> st.SearchStrategy[str]:
    # Registers start at 0: "!= v" and "<= v" hold at first, "== v" (v > 0) does not.
    return st.builds(lambda n, r, op, v: f"{n}.regs[{r}] {op} {v}",
                     st.sampled_from(names), st.integers(0, REGISTERS - 1),
                     st.sampled_from(ops), st.integers(1, MOD - 1))


@functools.cache
def _expr(names: tuple[str, ...], ops: tuple[str, ...]) -> st.SearchStrategy[str]:
    atom = _atom(names, ops)
    return st.one_of(atom, atom, st.builds(lambda a, op, b: f"({a}) {op} ({b})", atom,
                                           st.sampled_from(["and", "or"]), atom))


SAFE_OPS = ("!=", "<=")  # invariants: true in the initial world
GOAL_OPS = ("==", ">=")  # eventually, within, deadlock goals: false in the initial world


@st.composite
def _property(draw: st.DrawFn, index: int, names: tuple[str, ...]) -> dict[str, Any]:
    kind = draw(st.sampled_from(["invariant", "eventually", "within", "deadlock", "quiescence",
                                 "no_failure"]))
    prop: dict[str, Any] = {"name": f"p{index}_{kind}", "kind": kind}
    if kind == "invariant":
        prop["expr"] = draw(_expr(names, SAFE_OPS))
    elif kind in ("eventually", "within") or (kind == "deadlock" and draw(st.booleans())):
        prop["expr"] = draw(_expr(names, GOAL_OPS))
    if kind == "eventually" and _sometimes(draw, 2):  # a conjunction: maybe a rising goal
        prop["expr"] = " and ".join(draw(st.lists(_atom(names, (">=",)), min_size=2,
                                                  max_size=3)))
    if kind == "within":
        prop["within_ms"] = draw(st.sampled_from([5, 20, 60]))
    return prop


def _sometimes(draw: st.DrawFn, one_in: int) -> bool:
    """True about once in `one_in` draws; False is the simpler case hypothesis shrinks to."""
    return draw(st.integers(0, one_in - 1)) == one_in - 1


@st.composite
def _check(draw: st.DrawFn, names: Sequence[str]) -> dict[str, Any]:
    """Optional checker settings; each is absent more often than present."""
    check: dict[str, Any] = {}
    topics, services = topics_of(names), services_of(names)
    if _sometimes(draw, 4):
        check["latency"] = draw(st.one_of(
            st.sampled_from([[0, 1], [1, 2]]),
            st.builds(lambda t: {"default": [0, 0], t: [0, 2]}, st.sampled_from(topics))))
    faults: dict[str, Any] = {}
    if _sometimes(draw, 4):
        faults["drop"] = draw(st.lists(st.sampled_from(topics + services), min_size=1,
                                       max_size=2, unique=True))
    if _sometimes(draw, 6):
        faults["duplicate"] = draw(st.lists(st.sampled_from(topics), min_size=1, max_size=1))
    if _sometimes(draw, 4):
        crashing = draw(st.lists(st.sampled_from(names), min_size=1, max_size=2, unique=True))
        faults["crash"] = {"nodes": crashing, "max": 1,
                           "durable": draw(st.lists(st.sampled_from(crashing), max_size=1))}
    if faults:
        check["faults"] = faults
    if "latency" in check and draw(st.booleans()):
        check["deadline_ms"] = draw(st.sampled_from([0, 1]))
    if _sometimes(draw, 8):
        check["queue_bound"] = draw(st.integers(4, 8))
    return check


@st.composite
def systems(draw: st.DrawFn, *, max_nodes: int = 4, crowded: bool = False) -> dict[str, Any]:
    """A scenario mapping of 2..`max_nodes` program nodes, settings and properties.
    `crowded`: under `ros`, every node publishes on /bus at t=0 and n1's /bus handler is
    declared commutes=True (the messages that meet there are what the declaration is for)."""
    names = tuple(names_of(draw(st.integers(2, max_nodes))))
    semantics = "ros" if crowded else draw(st.sampled_from(["ros", "ros", "rebeca"]))
    check = {} if crowded else draw(_check(names))
    # Everyone publishing on /bus at t=0 only without latency and faults: their branches per
    # delivery would multiply the initial worlds (4 nodes x 4 subscribers x 2 delays = 65,536).
    bus_start = crowded or (not check and _sometimes(draw, 2))
    doc: dict[str, Any] = {"name": "generated", "semantics": semantics,
                           "nodes": [draw(_node(n, names, semantics, bus_start,
                                                "commuting" if crowded and n == "n1" else None))
                                     for n in names]}
    doc["properties"] = [draw(_property(i, names)) for i in range(draw(st.integers(1, 3)))]
    if semantics == "rebeca" and _sometimes(draw, 4):
        check["global_priority"] = True
    if check:
        doc["check"] = check
    return doc


def write_scenario(doc: dict[str, Any], path: Path) -> Path:
    """Write a drawn scenario mapping as YAML to `path` and return it."""
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path
