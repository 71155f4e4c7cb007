"""Parameter overrides, ROS 2 style: one syntax and one validation for every command.

``r1.speed:=0.4`` (or ``--param r1.speed=0.4``) sets parameter `speed` of node
r1; ``scan_rate_ms:=50`` without a node sets the scenario's common ``params``.
Values are YAML (``0.4``, ``[5, 5]``, ``true``). `launch`, `check` (every
mode: exhaustive, on workers, statistical simulations in every process),
`validate`, `experiment`, node processes and the pytest API (`twinfleet.testing`)
all load a scenario with its overrides through `load_with_params`, so a bad
override is the same one-line error everywhere (an unknown name ends with a
"did you mean") and what is checked is what is launched. A trace records the
overrides it was found with and `replay` applies them again.

`add_override_arguments` defines the words and the flag on a command's parser
without importing anything heavy (the parser of `check` must stay light).
"""

from __future__ import annotations

import argparse
import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml

from twinfleet.runtime.scenario.suggest import did_you_mean

if TYPE_CHECKING:
    from twinfleet.runtime.scenario.spec import Scenario


def add_override_arguments(parser: argparse.ArgumentParser, *, words: bool = True) -> None:
    """Add the ``[NODE.]NAME:=VALUE`` words and ``--param`` to a command that takes a scenario
    (`words` False: only ``--param``, for a command whose own positional words take them,
    `split_words`)."""
    if words:
        parser.add_argument("overrides", nargs="*", metavar="[NODE.]NAME:=VALUE",
                            help="parameter overrides, ROS 2 style: r1.speed:=0.4 sets r1's "
                                 "speed, scan_rate_ms:=50 every node's (values are YAML)")
    parser.add_argument("--param", action="append", default=[], metavar="[NODE.]NAME=VALUE",
                        help="a parameter override, as NAME:=VALUE (repeatable); `twinfleet "
                             "param get` shows the values in force in a running fleet")


def override_words(command: str, words: Sequence[str], flags: Sequence[str]) -> list[str]:
    """The overrides of a command line: ``NAME:=VALUE`` words, then ``--param`` values.

    Raises:
        ValueError: a word that is not an override (one line naming it).
    """
    for word in words:
        if ":=" not in word:
            raise ValueError(f"{command}: unexpected argument {word!r}; parameter overrides "
                             "look like r1.speed:=0.4")
    return [*words, *flags]


def split_words(words: Sequence[str]) -> tuple[list[str], list[str]]:
    """(the other words, the ``NAME:=VALUE`` overrides) of a list of positional words."""
    return [w for w in words if ":=" not in w], [w for w in words if ":=" in w]


def parse_param(text: str) -> tuple[str | None, str, Any]:
    """``r1.speed=0.4`` or ``r1.speed:=0.4`` → ("r1", "speed", 0.4); no node → (None, name, v).

    Raises:
        ValueError: not NAME=VALUE, or a value that is not YAML.
    """
    name, sep, raw = text.partition(":=") if ":=" in text else text.partition("=")
    name = name.strip()
    if not sep or not name or any(c.isspace() for c in name):
        raise ValueError(f"parameter override {text!r}: expected [NODE.]NAME=VALUE, "
                         "e.g. r1.speed=0.4")
    try:
        value = yaml.safe_load(raw) if raw.strip() else ""
    except yaml.YAMLError as exc:
        raise ValueError(f"parameter override {text!r}: the value is not YAML "
                         f"({str(exc).splitlines()[0]})") from None
    node, _, param = name.rpartition(".")
    return (node or None), param, value


def overrides_doc(path: Path, params: Sequence[str]) -> dict[str, Any]:
    """The top-level keys (`nodes`, `params`) of scenario `path` with `params` applied.

    Raises:
        ValueError: a malformed override, or one naming a node the scenario does not have.
    """
    doc = yaml.safe_load(path.read_text())
    nodes = [dict(n) if isinstance(n, dict) else n for n in doc.get("nodes") or []]
    common = dict(doc.get("params") or {})
    for text in params:
        node, name, value = parse_param(text)
        if node is None:
            common[name] = value
            continue
        entry = next((n for n in nodes if isinstance(n, dict) and n.get("name") == node), None)
        if entry is None:
            names = [str(n.get("name")) for n in nodes if isinstance(n, dict)]
            raise ValueError(f"parameter override {text!r}: {path} has no node {node!r} "
                             f"(nodes: {', '.join(names)}){did_you_mean(node, names)}")
        entry["params"] = {**(entry.get("params") or {}), name: value}
    out: dict[str, Any] = {"nodes": nodes}
    if common:
        out["params"] = common
    return out


def load_with_params(path: str | Path, params: Sequence[str] = (),
                     overrides: Mapping[str, Any] | None = None) -> Scenario:
    """`load_scenario(path, overrides)` with parameter overrides applied and validated.

    Raises:
        ScenarioError: the file or an override is invalid (the text names which).
    """
    from twinfleet.runtime.scenario.spec import ScenarioError, load_scenario

    scenario = load_scenario(path, overrides)  # the file's own errors first, as they are
    if not params or scenario.path is None:
        return scenario
    try:
        doc = overrides_doc(scenario.path, params)
    except ValueError as exc:
        raise ScenarioError(str(exc)) from None
    _check_node_overrides(scenario, params)
    fields = {f.name for cfg in scenario.nodes for f in dataclasses.fields(cfg.cls.Params)}
    for name in (doc.get("params") or {}):  # the file's own are declared (runtime.scenario.spec)
        if name not in fields:
            raise ScenarioError(f"{scenario.path}: parameter override {name!r}: no node of the "
                                f"scenario has that parameter{did_you_mean(name, fields)}")
    return load_scenario(scenario.path, {**(overrides or {}), **doc})


def _check_node_overrides(scenario: Scenario, params: Sequence[str]) -> None:
    """A ``NODE.NAME`` override names a parameter NODE declares: the error quotes the
    override the user typed, not the scenario file's key it would have been merged into."""
    from twinfleet.runtime.scenario.spec import ScenarioError

    declared = {cfg.name: [f.name for f in dataclasses.fields(cfg.cls.Params)]
                for cfg in scenario.nodes}
    for text in params:
        node, name, _value = parse_param(text)
        known = declared.get(node or "")
        if known is not None and name not in known:
            raise ScenarioError(
                f"parameter override {text!r}: node {node!r} has no parameter {name!r} "
                f"(it has: {', '.join(known) or 'none'}){did_you_mean(name, known)}")


def load(path: str | Path, *, semantics: str | None = None,
         params: Sequence[str] = ()) -> Scenario:
    """Load a scenario as `check` does: an optional semantics override and parameter
    overrides (``r1.speed:=0.4``, validated as `launch` validates them)."""
    overrides: dict[str, Any] = {}
    if semantics is not None:
        overrides["semantics"] = semantics
    return load_with_params(path, params, overrides)


def scenario_common(path: str | Path) -> dict[str, Any]:
    """The common ``params`` of a scenario file, as written."""
    doc = yaml.safe_load(Path(path).read_text())
    return dict(doc.get("params") or {}) if isinstance(doc, dict) else {}
