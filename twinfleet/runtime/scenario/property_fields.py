"""Property fields checked against the initial states, before anything runs.

A property reads node states by field (``r1.battery``). A misspelt field
(``r1.batery``) is not a syntax error, so `property_eval` accepts it, and
both drivers would find it only when they first evaluate the expression: the
checker after building its initial worlds, a live run after starting every
process. `check_property_fields` builds each node the property reads, as both
drivers build it (the class, its parameters, before ``@on_start``), and looks
every ``NODE.FIELD`` and ``nodes['NODE'].FIELD`` of every expression up on that
state: a field the state does not have is a `ScenarioError` naming the
property, the field and the fields the state does have. `check`, `launch`
(before it starts a process) and the pytest API call it; node processes do
not, since their launcher already did.

Only the first field after a node is looked up: what a field holds can change
type as the node runs (``None``, then a tuple), so deeper reads are judged
where they are evaluated.
"""

from __future__ import annotations

import ast
import dataclasses
from collections.abc import Iterator, Sequence
from typing import Any

from twinfleet.runtime.scenario.spec import Scenario, ScenarioError


def _node_reads(tree: ast.AST, names: frozenset[str]) -> Iterator[tuple[str, str]]:
    """(node, field) of every ``NODE.FIELD`` and ``nodes['NODE'].FIELD`` in an expression."""
    for item in ast.walk(tree):
        if not isinstance(item, ast.Attribute):
            continue
        base = item.value
        if isinstance(base, ast.Name) and base.id in names:
            yield base.id, item.attr
        elif (isinstance(base, ast.Subscript) and isinstance(base.value, ast.Name)
              and base.value.id == "nodes" and isinstance(base.slice, ast.Constant)
              and base.slice.value in names):
            yield str(base.slice.value), item.attr


def nodes_read(source: str, node_names: Sequence[str]) -> frozenset[str] | None:
    """The nodes whose states an expression reads, by name or as ``nodes['NAME']``; None
    when it reads `nodes` any other way (a loop over it, a computed key): then any node.
    ``now`` reads no node. A report of a violation shows these nodes' states."""
    try:
        tree = ast.parse(source, mode="eval")
    except SyntaxError:
        return None
    names = frozenset(node_names) - _bound_names(tree)
    read = {n.id for n in ast.walk(tree) if isinstance(n, ast.Name) and n.id in names}
    uses = sum(1 for n in ast.walk(tree) if isinstance(n, ast.Name) and n.id == "nodes")
    keyed = [str(s.slice.value) for s in ast.walk(tree) if isinstance(s, ast.Subscript)
             and isinstance(s.value, ast.Name) and s.value.id == "nodes"
             and isinstance(s.slice, ast.Constant) and s.slice.value in names]
    return None if uses > len(keyed) else frozenset(read | set(keyed))


def _bound_names(tree: ast.AST) -> set[str]:
    """Names a comprehension binds (they hide a node of the same name)."""
    return {t.id for c in ast.walk(tree) if isinstance(c, ast.comprehension)
            for t in ast.walk(c.target) if isinstance(t, ast.Name)}


def state_fields(state: Any) -> list[str]:
    """The fields of a node state: a dataclass's fields, else its public attributes."""
    if dataclasses.is_dataclass(state) and not isinstance(state, type):
        return [f.name for f in dataclasses.fields(state)]
    if isinstance(state, dict):
        return sorted(str(k) for k in state)
    return sorted(a for a in getattr(state, "__dict__", {}) if not a.startswith("_"))


def check_property_fields(scenario: Scenario) -> None:
    """Refuse a property that reads a field no node state has (module docstring).

    Raises:
        ScenarioError: one line naming the property, the field and the state's real fields.
    """
    configs = {cfg.name: cfg for cfg in scenario.nodes}
    states: dict[str, Any] = {}
    for prop in scenario.properties:
        if prop.expr is None:
            continue
        try:
            tree = ast.parse(prop.expr, mode="eval")
        except SyntaxError:
            continue  # property_eval reports it, with where
        names = frozenset(configs) - _bound_names(tree)
        for node, name in _node_reads(tree, names):
            if node not in states:
                states[node] = configs[node].instantiate()
            state = states[node].state
            if isinstance(state, dict) or hasattr(state, name):
                continue
            hint = (f" ({name} is a parameter of {node}: properties read the nodes' states, "
                    "not their parameters; copy it into the state to read it)"
                    if hasattr(states[node].params, name) else "")
            raise ScenarioError(
                f"{scenario.source}: property {prop.name!r}: {node}.{name}: the state of "
                f"{node} ({type(state).__name__}) has no field {name!r}; its fields: "
                f"{', '.join(state_fields(state)) or '(none)'}{hint}")
