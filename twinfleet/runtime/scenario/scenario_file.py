"""A scenario written back as YAML, so that node processes can load one built in Python.

Live node processes load their scenario from a file (`runtime.fleet.node_main
--scenario`). For a scenario built with `Scenario.build` the launcher writes
one (`write_scenario`): node classes by ``module:qualname`` (refused for a
class that cannot be imported back under that name: one defined inside a
function or in the ``__main__`` script), every node's parameters in full, the
map path made absolute. The file is loaded back at once and compared with
the original, so what the processes run is what the caller built.
"""

from __future__ import annotations

import dataclasses
import importlib
from pathlib import Path
from typing import Any

import yaml

from twinfleet.runtime.scenario.config import to_mapping
from twinfleet.runtime.scenario.spec import NodeConfig, Scenario, ScenarioError, load_scenario


def importable_class_path(cls: type, where: str) -> str:
    """``module:qualname`` of `cls`, checked to import back to the same class."""
    path = f"{cls.__module__}:{cls.__qualname__}"
    if "<locals>" in cls.__qualname__:
        raise ScenarioError(f"{where}: node class {path} is defined inside a function; node "
                            "processes import their class by module:qualname, so define it at "
                            "the top level of a module")
    if cls.__module__ == "__main__":
        raise ScenarioError(f"{where}: node class {cls.__qualname__} is defined in the __main__ "
                            "script, which node processes cannot import; move it to a module")
    try:
        found: Any = importlib.import_module(cls.__module__)
        for part in cls.__qualname__.split("."):
            found = getattr(found, part)
    except (ImportError, AttributeError):
        found = None
    if found is None or (found is not cls and getattr(cls, "rclpy_class", None) is not found):
        raise ScenarioError(f"{where}: node class {path} does not import back under that name; "
                            "node processes need an importable module:qualname")
    return path


def to_document(scenario: Scenario) -> dict[str, Any]:
    """The scenario as a YAML mapping that loads back to an equal scenario."""
    doc: dict[str, Any] = {"name": scenario.name, "fleet": scenario.fleet,
                           "description": scenario.description,
                           "semantics": scenario.semantics, "seed": scenario.seed}
    if scenario.scene is not None:
        doc["scene"] = scenario.scene
    doc["nodes"] = [_node(i, cfg, scenario.source) for i, cfg in enumerate(scenario.nodes)]
    doc["properties"] = [{k: v for k, v in dataclasses.asdict(p).items() if v is not None}
                         for p in scenario.properties]
    for key, config in (("check", scenario.check), ("live", scenario.live)):
        if mapping := to_mapping(config):
            doc[key] = mapping
    return doc


def _node(i: int, cfg: NodeConfig, source: str) -> dict[str, Any]:
    params = {f.name: _plain(getattr(cfg.params, f.name)) for f in dataclasses.fields(cfg.params)}
    return {"name": cfg.name, "class": importable_class_path(cfg.cls, f"{source}: nodes[{i}]"),
            "namespace": cfg.namespace, "priority": cfg.priority,
            "respawn": cfg.respawn, "params": params}


def _plain(value: Any) -> Any:
    return [_plain(v) for v in value] if isinstance(value, tuple | list) else value


def write_scenario(scenario: Scenario, path: str | Path) -> Scenario:
    """Write `scenario` to `path` and return it loaded from there (its `path` set).

    Raises `ScenarioError` when a node class cannot be imported by name, a parameter
    has no YAML form, or the file does not load back to the same scenario.
    """
    doc = to_document(scenario)
    try:
        text = yaml.safe_dump(doc, sort_keys=False)
    except yaml.YAMLError as exc:
        raise ScenarioError(f"{scenario.source}: cannot be written as YAML for node "
                            f"processes ({exc})") from None
    path = Path(path)
    path.write_text(f"# {scenario.source}, written for its node processes.\n{text}")
    loaded = load_scenario(path)
    for before, after in zip(scenario.nodes, loaded.nodes, strict=True):
        if (before.cls, before.params) != (after.cls, after.params):
            raise ScenarioError(f"{scenario.source}: node {before.name}: its parameters do not "
                                f"survive the YAML round trip ({before.params!r} became "
                                f"{after.params!r})")
    return loaded
