"""Scenario files: every shipped one loads; bad ones fail naming file, key and rule."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from twinfleet.runtime.scenario import ScenarioError, load_scenario

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = sorted((ROOT / "launch").glob("*.yaml"))
GOOD = {
    "name": "t",
    "map": str(ROOT / "maps" / "corridor12.yaml"),
    "nodes": [
        {"name": "map_server", "class": "twinfleet.nodes.map_server:MapServer", "params": {"robots": ["r1"]}},
        {"name": "r1", "class": "twinfleet.nodes.robot:Robot", "namespace": "/r1",
         "params": {"start": [5, 1], "goal": [5, 10]}},
    ],
}


def write(tmp_path: Path, doc: dict) -> Path:
    path = tmp_path / "scenario.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


@pytest.mark.parametrize("path", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_every_shipped_scenario_loads(path):
    scenario = load_scenario(path)
    assert scenario.nodes


def test_good_scenario_builds_typed_parameters(tmp_path):
    scenario = load_scenario(write(tmp_path, GOOD))
    r1 = scenario.node("r1")
    assert r1.params.start == (5, 1)
    assert r1.params.map == GOOD["map"]
    assert r1.namespace == "/r1"


def mutate(path: str, value):
    doc = yaml.safe_load(yaml.safe_dump(GOOD))
    *parents, last = path.split(".")
    target = doc
    for key in parents:
        target = target[int(key)] if key.isdigit() else target[key]
    if value is KeyError:
        del target[last]
    else:
        target[last] = value
    return doc


@pytest.mark.parametrize(
    ("path", "value", "expected"),
    [
        ("nodes.1.class", "twinfleet.nodes.robot:Robott", r"nodes\[1\]\.class: unknown node class 'twinfleet.nodes.robot:Robott'"),
        ("nodes.1.class", "twinfleet.nodes.robot", r"expected 'module:Class'"),
        ("nodes.1.params.speeed", 0.5, r"nodes\[1\]\.params\.speeed: unknown parameter of RobotParams"),
        ("nodes.1.params.start", "five", r"nodes\[1\]\.params\.start: expected a list"),
        ("nodes.1.params.start", [5], r"expected 2 values"),
        ("nodes.1.params.speed", "fast", r"nodes\[1\]\.params\.speed: expected float"),
        ("nodes.1.params.goal", KeyError, r"nodes\[1\]\.params\.goal: missing"),
        ("nodes.1.params.start", [0, 4], r"nodes\[1\] \(r1\): r1: start \[0, 4\] lies inside an obstacle"),
        ("nodes.1.params.goal", [30, 4], r"goal \[30, 4\] is outside the 12x12 map"),
        ("nodes.1.params.speed", 3.0, r"Eq\. 1"),
        ("nodes.1.name", "map_server", r"node name 'map_server' is used twice"),
        ("nodes.1.name", "1robot", r"invalid node name"),
        ("profile", "fast", r"profile: expected one of fixed, rebeca"),
        ("semantics", "dds", r"semantics: expected one of ros, rebeca"),
        ("map", "nowhere.yaml", r"map: file .* does not exist"),
        ("nodez", [], r"nodez: unknown key"),
        ("nodes", [], r"nodes: expected a non-empty list"),
        ("properties", [{"kind": "always"}], r"properties\[0\]\.kind: expected one of"),
        ("properties", [{"kind": "invariant"}], r"needs an expression"),
        ("properties", [{"kind": "invariant", "expr": "a ==="}], r"not a Python expression"),
        ("check", {"max_state": 1}, r"check\.max_state: unknown key"),
    ],
)
def test_bad_scenario_names_file_key_and_rule(tmp_path, path, value, expected):
    bad = write(tmp_path, mutate(path, value))
    with pytest.raises(ScenarioError, match=expected) as info:
        load_scenario(bad)
    assert str(bad) in str(info.value)


def test_unreadable_and_non_yaml_files(tmp_path):
    with pytest.raises(ScenarioError, match="cannot read"):
        load_scenario(tmp_path / "missing.yaml")
    broken = tmp_path / "broken.yaml"
    broken.write_text("nodes: [\n")
    with pytest.raises(ScenarioError, match="not valid YAML"):
        load_scenario(broken)
