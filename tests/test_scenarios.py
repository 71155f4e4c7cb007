"""Scenario files: every shipped one loads (also by name); bad ones fail naming file, key and
rule, `check:` and `live:` included; `twinfleet examples` lists and copies them."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from twinfleet.cli import main as cli
from twinfleet.runtime.fleet.launcher import wall_limit
from twinfleet.runtime.scenario.config import (
    CheckConfig,
    CrashConfig,
    FaultConfig,
    LiveConfig,
    PerName,
)
from twinfleet.runtime.scenario.examples import shipped_scenarios
from twinfleet.runtime.scenario.lint import lint_scenario
from twinfleet.runtime.scenario.spec import ScenarioError, load_scenario, resolve_scenario

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = sorted((ROOT / "twinfleet" / "launch").glob("*.yaml"))
GOOD = {
    "name": "t",
    "params": {"map": str(ROOT / "twinfleet" / "maps" / "corridor12.yaml")},
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


def test_robot_scenarios_name_the_robot_scene_and_others_none():
    named = {p.stem: load_scenario(p).scene for p in SHIPPED}
    assert named.pop("demo") is None
    assert set(named.values()) == {"twinfleet.nodes.scene:RobotScene"}


def test_a_scene_is_kept_when_a_scenario_is_written_for_node_processes(tmp_path):
    from twinfleet.runtime.scenario.scenario_file import write_scenario
    from twinfleet.runtime.scenario.spec import Scenario

    built = Scenario.build("t", GOOD["nodes"], params=GOOD["params"],
                           scene="twinfleet.nodes.scene:RobotScene")
    assert write_scenario(built, tmp_path / "t.yaml").scene == built.scene


def test_good_scenario_builds_typed_parameters(tmp_path):
    scenario = load_scenario(write(tmp_path, GOOD))
    r1 = scenario.node("r1")
    assert r1.params.start == (5, 1)
    assert r1.params.map == GOOD["params"]["map"]
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
        ("params.profile", "fast", r"nodes\[0\] \(map_server\): .*fast"),
        ("profile", "rebeca", r"^\S+: profile: unknown key; expected one of .* \(a parameter of "
                              r"the nodes goes under params:, as params: \{profile: \.\.\.\}\)$"),
        ("semantics", "dds", r"semantics: expected one of ros, rebeca"),
        ("params.map", "nowhere.yaml", r"nodes\[0\]\.params\.map: file .*nowhere\.yaml does not exist"),
        ("map", "../maps/map50.yaml", r"map: unknown key; .*params: \{map: \.\.\.\}"),
        ("nodez", [], r"nodez: unknown key"),
        ("nodes", [], r"nodes: expected a non-empty list"),
        ("properties", [{"kind": "always"}], r"properties\[0\]\.kind: expected one of"),
        ("properties", [{"kind": "invariant"}], r"needs an expression"),
        ("properties", [{"kind": "invariant", "expr": "a ==="}], r"not a Python expression"),
        ("check", {"max_state": 1}, r"check\.max_state: unknown key"),
        ("check", [1], r"check: expected a mapping with search, max_states"),
        ("check", {"search": "astar"}, r"check\.search: expected one of bfs, dfs, random"),
        ("check", {"max_states": -5}, r"check\.max_states: expected a whole number >= 0"),
        ("check", {"max_depth": 2.5}, r"check\.max_depth: expected a whole number"),
        ("check", {"max_time_s": "1h"}, r"check\.max_time_s: expected seconds"),
        ("check", {"global_priority": "yes"}, r"check\.global_priority: expected true or false"),
        ("check", {"latency": [5, 1]}, r"check\.latency: latency must be \[min, max\] with 0"),
        ("check", {"latency": {"default": 3}}, r"check\.latency\.default: expected \[min, max\]"),
        ("check", {"latency": {"/r1/scan": [0]}}, r"check\.latency\./r1/scan: expected \[min"),
        ("check", {"deadline_ms": {"/poses": -1}}, r"check\.deadline_ms\./poses: expected milli"),
        ("check", {"queue_bound": 0}, r"check\.queue_bound: expected a number of pending events"),
        ("check", {"queue_bound": {"r9": 3}}, r"check\.queue_bound\.r9: 'r9' is not a node of "
                                              r"this scenario; expected one of map_server, r1"),
        ("check", {"faults": {"drop": "/poses"}}, r"check\.faults\.drop: expected a list of names"),
        ("check", {"faults": {"explode": 1}}, r"check\.faults\.explode: unknown key"),
        ("check", {"faults": {"crash": {"max": 1}}}, r"check\.faults\.crash\.nodes: missing"),
        ("check", {"faults": {"crash": {"nodes": ["r1"], "max": 0}}}, r"crash\.max: expected a "
                                                                     r"number of crashes >= 1"),
        ("check", {"faults": {"crash": {"nodes": ["r1"], "durable": ["r7"]}}},
         r"check\.faults\.crash: 'r7' is not a node"),
        ("live", {"timeout": 3}, r"live\.timeout: unknown key; expected one of horizon_s, max_nodes, "
                                 r"max_payload_bytes, report, stop, stop_on_error, summary_topics, "
                                 r"time_scale, timeout_s, wall_timeout_s"),
        ("live", {"horizon_s": -1}, r"live\.horizon_s: expected a number > 0"),
        ("live", {"timeout_s": 3, "wall_timeout_s": 4}, r"live\.timeout_s: give "
                                                        r"live\.wall_timeout_s only"),
        ("live", {"stop": "never"}, r"live\.stop: expected one of timeout, settled, violation"),
        ("live", {"wall_timeout_s": 0}, r"live\.wall_timeout_s: expected a number > 0"),
        ("live", {"time_scale": "fast"}, r"live\.time_scale: expected a number > 0"),
        ("live", {"stop_on_error": 1}, r"live\.stop_on_error: expected true or false"),
        ("live", {"report": "nodes.report"}, r"live\.report: expected 'module:factory'"),
        ("live", {"report": "no.such:factory"}, r"live\.report: unknown report factory"),
        ("live", {"summary_topics": "/poses"}, r"live\.summary_topics: expected a list of names"),
        ("scene", 3, r"scene: expected a str"),
        ("scene", "twinfleet.nodes.scene", r"scene: expected 'module:Scene'"),
        ("scene", "twinfleet.nodes.scene:NoScene", r"scene: unknown scene"),
        ("scene", "twinfleet.nodes.scene:point", r"scene: twinfleet\.nodes\.scene:point\(\) raised "
                                                  r"TypeError"),
        ("scene", "twinfleet.nodes.msgs:Path", r"scene: twinfleet\.nodes\.msgs:Path\(\) raised"),
        ("scene", "twinfleet.nodes.scene:HALF_M", r"scene: twinfleet\.nodes\.scene:HALF_M is a "
                                                   r"float, not a scene class"),
        ("scene", "builtins:dict", r"scene: builtins:dict\(\) made a dict, not a scene"),
    ],
)
def test_bad_scenario_names_file_key_and_rule(tmp_path, path, value, expected):
    bad = write(tmp_path, mutate(path, value))
    with pytest.raises(ScenarioError, match=expected) as info:
        load_scenario(bad)
    assert str(bad) in str(info.value)


def test_the_old_timeout_key_is_read_as_wall_time_with_a_one_line_warning(tmp_path):
    old = load_scenario(write(tmp_path, {**GOOD, "live": {"timeout_s": 30}}))
    assert (old.live.wall_timeout_s, old.live.horizon_s, old.live.timeout_s) == (30.0, None, None)
    (warning,) = [str(w) for w in lint_scenario(old) if "timeout_s" in str(w)]
    assert "\n" not in warning and warning.startswith(f"warning: {old.path}: live.timeout_s is "
                                                      "deprecated: taken as live.wall_timeout_s")
    assert "live.horizon_s" in warning
    new = load_scenario(write(tmp_path, {**GOOD, "live": {"horizon_s": 30}}))
    assert not [w for w in lint_scenario(new) if "timeout_s" in str(w)]


def test_a_launch_ends_at_the_first_of_its_wall_timeout_and_its_fleet_time_horizon():
    assert wall_limit(None, None, 5)[0] is None
    assert wall_limit(20, None, 5) == (20, "timeout after 20 s")
    assert wall_limit(None, 120, 5) == (24, "the fleet-time horizon of 120 s (24 s of wall "
                                            "time at time scale 5)")
    assert wall_limit(20, 120, 5)[0] == 20 and wall_limit(30, 120, 5)[0] == 24
    for scenario in shipped_scenarios().values():  # each shipped scenario says fleet seconds
        assert load_scenario(scenario).live.horizon_s is not None, scenario


def test_unreadable_and_non_yaml_files(tmp_path):
    with pytest.raises(ScenarioError, match="cannot read scenario file: no such file"):
        load_scenario(tmp_path / "missing.yaml")
    with pytest.raises(ScenarioError, match="cannot read scenario file: Is a directory"):
        load_scenario(tmp_path)
    broken = tmp_path / "broken.yaml"
    broken.write_text("nodes: [\n")
    with pytest.raises(ScenarioError, match="not valid YAML"):
        load_scenario(broken)


def test_check_and_live_sections_become_typed_frozen_config(tmp_path):
    doc = {**GOOD, "check": {"max_states": 500, "max_time_s": 2, "latency": {"default": [0, 5],
                                                                         "/r1/scan": [0, 0]},
                             "deadline_ms": 50, "queue_bound": {"default": 8, "r1": 20},
                             "faults": {"drop": ["/poses"], "crash": {"nodes": ["r1"]}}},
           "live": {"wall_timeout_s": 30, "summary_topics": ["/poses"]}}
    scenario = load_scenario(write(tmp_path, doc))
    check, live = scenario.check, scenario.live
    assert check == CheckConfig(max_states=500, max_time_s=2.0,
                                latency=PerName((0, 5), (("/r1/scan", (0, 0)),)),
                                deadline_ms=PerName(50), queue_bound=PerName(8, (("r1", 20),)),
                                faults=FaultConfig(drop=("/poses",), crash=CrashConfig(("r1",))))
    assert isinstance(check.max_time_s, float) and check.search is None
    assert check.queue_bound.get("r1") == 20 and check.queue_bound.get("map_server") == 8
    assert live == LiveConfig(wall_timeout_s=30.0, summary_topics=("/poses",))
    with pytest.raises(AttributeError):
        check.max_states = 1  # type: ignore[misc]
    defaults = load_scenario(write(tmp_path, GOOD))
    assert (defaults.check, defaults.live) == (CheckConfig(), LiveConfig())


def test_shipped_scenarios_resolve_by_name_from_any_directory(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    shipped = shipped_scenarios()
    assert set(shipped) == {p.stem for p in SHIPPED}
    assert resolve_scenario("c1a") == ROOT / "twinfleet" / "launch" / "c1a.yaml"
    assert resolve_scenario("c1a.yaml") == ROOT / "twinfleet" / "launch" / "c1a.yaml"
    scenario = load_scenario("c1a_rebeca")
    assert scenario.path == ROOT / "twinfleet" / "launch" / "c1a_rebeca.yaml"
    assert scenario.node("r1").params.map == str(ROOT / "twinfleet" / "maps" / "map50.yaml")
    assert scenario.live.report == "twinfleet.nodes.report:report_for"
    # A file of that name in the working directory wins: a path still works as it did.
    (tmp_path / "c1a").write_text(yaml.safe_dump({**GOOD, "name": "mine"}))
    assert load_scenario("c1a").name == "mine"
    with pytest.raises(ScenarioError, match=r"^nope: cannot read scenario file: no such file, "
                                            r"and no shipped example is called 'nope' \(shipped: "
                                            r"c1a, c1a_rebeca, .*headon; `twinfleet examples`"):
        load_scenario("nope")
    with pytest.raises(ScenarioError, match="no shipped example is called 'c1b'"):
        load_scenario("sub/c1b")  # a path, not a name


def test_examples_lists_names_and_descriptions(capsys):
    assert cli(["examples"]) == 0
    lines = capsys.readouterr().out.splitlines()
    listed = {line.split()[0]: line.split(None, 1)[1] for line in lines if line and
              not line.startswith("run one")}
    assert set(listed) == {p.stem for p in SHIPPED}
    assert listed["headon"] == load_scenario(ROOT / "twinfleet" / "launch" / "headon.yaml").description


def test_examples_copy_writes_an_editable_scenario_and_its_map(tmp_path, capsys):
    assert cli(["examples", "--copy", "headon", str(tmp_path / "mine")]) == 0
    out = capsys.readouterr().out
    copied = tmp_path / "mine" / "headon.yaml"
    assert f"wrote {copied}" in out
    assert sorted(p.name for p in copied.parent.iterdir()) == \
        ["corridor12.pgm", "corridor12.yaml", "headon.yaml"]
    original = (ROOT / "twinfleet" / "launch" / "headon.yaml").read_text()
    assert copied.read_text() == original.replace("  map: ../maps/corridor12.yaml",
                                                  "  map: corridor12.yaml")
    scenario = load_scenario(copied)
    assert scenario.node("map_server").params.map == str(copied.parent / "corridor12.yaml")
    assert cli(["examples", "--copy", "headon", str(copied.parent)]) == 2
    assert "headon.yaml exists; not overwritten" in capsys.readouterr().err
    assert cli(["examples", "--copy", "nope"]) == 2
    assert "nope: no shipped example of that name (shipped: c1a," in capsys.readouterr().err


def test_examples_sharing_a_map_keep_the_first_copy(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert cli(["examples", "--copy", "c1a"]) == 0
    (tmp_path / "map50.yaml").write_text((tmp_path / "map50.yaml").read_text() + "# edited\n")
    assert cli(["examples", "--copy", "c1a_rebeca"]) == 0
    out = capsys.readouterr().out
    assert "kept existing map50.yaml" in out and "wrote c1a_rebeca.yaml" in out
    assert (tmp_path / "map50.yaml").read_text().endswith("# edited\n")
    assert load_scenario("c1a_rebeca.yaml").node("r1").params.map == str(tmp_path / "map50.yaml")


def test_a_mistyped_class_name_gets_a_did_you_mean(tmp_path):
    doc = {"name": "typo", "nodes": [{"name": "l", "class": "twinfleet.nodes.demo:Listenr"}]}
    with pytest.raises(ScenarioError, match=r"unknown node class 'twinfleet\.nodes\.demo:Listenr'"
                                            r" .*; did you mean 'twinfleet\.nodes\.demo:Listener'\?"):
        load_scenario(write(tmp_path, doc))


def test_a_name_with_no_example_package_registered_asks_for_a_path(monkeypatch):
    # A library caller (not the command line, not twinfleet.testing) has registered no
    # example package: the error says how to find the file, not "shipped: " with nothing.
    from twinfleet.runtime.scenario import examples

    monkeypatch.setattr(examples, "_PACKAGES", [])
    with pytest.raises(ScenarioError, match=r"^c1a: cannot read scenario file: no such file, and "
                       r"no example package is registered to find it by name: pass the file's "
                       r"path, or register one first \(twinfleet\.runtime\.scenario\.examples\."
                       r"add_examples; the command line and twinfleet\.testing register the "
                       r"shipped examples\)$"):
        load_scenario("c1a")
