"""Scenarios built in Python (no YAML file): checked, written for node processes, run live."""

from __future__ import annotations

import asyncio
import io
import json
import tempfile
from pathlib import Path
from typing import Any

import pytest
import yaml

from tests.checker.models import Num, Ping, PingParams, Pong
from twinfleet import Node
from twinfleet.checker import CheckOptions, PropertySet, System, check
from twinfleet.runtime.scenario.config import CheckConfig, ConfigError, LiveConfig, PerName
from twinfleet.runtime.scenario.scenario_file import to_document, write_scenario
from twinfleet.runtime.scenario.spec import (
    NodeEntry,
    PropertyConfig,
    Scenario,
    ScenarioError,
    load_scenario,
)

BOUNDED = PropertyConfig("bounded", "invariant", "ping.sent - pong.received <= 1")
PING_PONG_YAML = """\
name: pingpong
nodes:
  - {name: ping, class: "tests.checker.models:Ping", params: {rounds: 3}}
  - {name: pong, class: "tests.checker.models:Pong"}
properties:
  - {name: bounded, kind: invariant, expr: "ping.sent - pong.received <= 1"}
"""


def ping_pong(**kwargs: Any) -> Scenario:
    """The ping-pong pair of tests/checker/test_counts.py, built from class objects."""
    return Scenario.build("pingpong", [NodeEntry("ping", Ping, {"rounds": 3}),
                                       NodeEntry("pong", Pong)], properties=[BOUNDED], **kwargs)


def test_a_python_scenario_checks_with_the_counts_of_its_yaml_twin(tmp_path: Path) -> None:
    # test_counts.py derives 7 states, 6 transitions by hand for the YAML version.
    yaml_path = tmp_path / "pingpong.yaml"
    yaml_path.write_text(PING_PONG_YAML)
    from_file, from_python = check(yaml_path), check(ping_pong())
    for result in (from_file, from_python):
        assert result.status == "holds"
        assert (result.statistics.states, result.statistics.transitions) == (7, 6)
    assert from_python.scenario == "<scenario pingpong>"
    python, loaded = ping_pong(), load_scenario(yaml_path)
    assert [(n.name, n.cls, n.params) for n in python.nodes] == \
        [(n.name, n.cls, n.params) for n in loaded.nodes]
    assert (python.properties, python.check, python.live) == \
        (loaded.properties, loaded.check, loaded.live)


def test_params_instances_class_paths_and_property_mappings_mix() -> None:
    scenario = Scenario.build("pp", [NodeEntry("ping", Ping, PingParams(rounds=2)),
                                     NodeEntry("pong", "tests.checker.models:Pong")],
                              properties=[{"name": "b", "kind": "invariant",
                                           "expr": "ping.sent <= 2"}])
    assert scenario.node("ping").params == PingParams(rounds=2)
    assert System(scenario, properties=PropertySet.from_scenario(scenario)).names == ("ping", "pong")
    result = check(scenario)
    # Two rounds: ping, pong, ping, pong, then nothing: 5 worlds, 4 steps (as test_counts).
    assert result.status == "holds"
    assert (result.statistics.states, result.statistics.transitions) == (5, 4)


def test_a_violation_in_a_python_scenario_has_a_trace_without_a_file() -> None:
    scenario = Scenario.build("pp", [NodeEntry("ping", Ping, {"rounds": 3}),
                                     NodeEntry("pong", Pong)],
                              properties=[PropertyConfig("few", "invariant", "ping.sent < 3")])
    result = check(scenario, CheckOptions(trace_out=None))
    assert result.status == "violated" and result.violation.property == "few"
    assert result.trace is not None and result.trace["scenario"] is None
    with pytest.raises(ScenarioError, match="needs a scenario file"):
        check(scenario, CheckOptions(checkpoint="x.ckpt"))


def test_check_settings_of_a_python_scenario_are_the_typed_config() -> None:
    scenario = ping_pong(check={"latency": [0, 5], "queue_bound": {"pong": 2}})
    assert scenario.check.latency == PerName((0, 5))
    assert scenario.check.queue_bound.get("pong") == 2
    assert scenario.check.queue_bound.get("ping") is None
    assert ping_pong(check=CheckConfig(latency=(0, 5))).check == \
        ping_pong(check={"latency": [0, 5]}).check


@pytest.mark.parametrize(("kwargs", "expected"), [
    ({"check": {"max_states": "many"}}, r"^<scenario pingpong>: check\.max_states: expected a "
                                        r"whole number"),
    ({"check": {"queue_bound": {"nobody": 2}}}, r"check\.queue_bound\.nobody: 'nobody' is not a "
                                                 r"node"),
    ({"live": LiveConfig(timeout_s=3)}, None),
    ({"semantics": "fast"}, r"<scenario pingpong>: semantics: expected one of ros, rebeca"),
])
def test_python_scenarios_fail_as_files_do(kwargs: dict[str, Any], expected: str | None) -> None:
    if expected is None:
        assert ping_pong(**kwargs).live.wall_timeout_s == 3.0  # the old key, taken as wall time
        return
    with pytest.raises(ScenarioError, match=expected):
        ping_pong(**kwargs)


def test_bad_node_entries_name_the_entry() -> None:
    with pytest.raises(ScenarioError, match=r"nodes\[0\]\.class: expected 'module:Class' or a "
                                            r"Node subclass, got 42"):
        Scenario.build("x", [NodeEntry("a", 42)])  # type: ignore[arg-type]
    with pytest.raises(ScenarioError, match=r"nodes\[0\]\.class: 'builtins:dict' is not a "
                                            r"subclass"):
        Scenario.build("x", [NodeEntry("a", dict)])  # type: ignore[arg-type]
    with pytest.raises(ScenarioError, match=r"nodes\[0\]\.params\.round: unknown parameter"):
        Scenario.build("x", [NodeEntry("a", Ping, {"round": 3})])
    with pytest.raises(ConfigError, match=r"check\.search: expected one of bfs, dfs, random"):
        CheckConfig(search="astar")


def test_a_python_scenario_is_written_for_node_processes_and_loads_back(tmp_path: Path) -> None:
    scenario = ping_pong(check=CheckConfig(latency={"default": (0, 2), "/pong": (0, 0)},
                                           faults={"crash": {"nodes": ["pong"]}}),
                         live=LiveConfig(time_scale=2.0, summary_topics=("/pong",)))
    doc = to_document(scenario)
    assert doc["nodes"][0]["class"] == "tests.checker.models:Ping"
    assert doc["check"] == {"latency": {"default": [0, 2], "/pong": [0, 0]},
                            "faults": {"crash": {"nodes": ["pong"]}}}
    loaded = write_scenario(scenario, tmp_path / "pp.yaml")
    assert loaded.path == tmp_path / "pp.yaml"
    assert yaml.safe_load(loaded.path.read_text())["live"] == {"time_scale": 2.0,
                                                             "summary_topics": ["/pong"]}
    assert (loaded.check, loaded.live, loaded.properties) == \
        (scenario.check, scenario.live, scenario.properties)
    assert check(loaded).statistics.states == check(scenario).statistics.states


class Local(Node):
    """Importable by module:qualname (a module-level class of this test module)."""


def test_only_importable_node_classes_can_be_written(tmp_path: Path) -> None:
    class Inner(Node):
        pass

    assert write_scenario(Scenario.build("ok", [NodeEntry("a", Local)]), tmp_path / "ok.yaml")
    with pytest.raises(ScenarioError, match=r"<scenario inner>: nodes\[0\]: node class "
                                            r".*<locals>\.Inner is defined inside a function"):
        write_scenario(Scenario.build("inner", [NodeEntry("a", Inner)]), tmp_path / "x.yaml")
    Inner.__module__, Inner.__qualname__ = "__main__", "Inner"
    with pytest.raises(ScenarioError, match="defined in the __main__ script"):
        write_scenario(Scenario.build("main", [NodeEntry("a", Inner)]), tmp_path / "x.yaml")
    Inner.__module__, Inner.__qualname__ = __name__, "Renamed"
    with pytest.raises(ScenarioError, match="does not import back under that name"):
        write_scenario(Scenario.build("renamed", [NodeEntry("a", Inner)]), tmp_path / "x.yaml")


# ----------------------------------------------------------------------- live


class PongReport:
    """A run report (`live.report`) that finishes when the last /pong arrives."""

    def __init__(self, rounds: int) -> None:
        self.rounds, self.seen = rounds, []

    def topics(self) -> list[str]:
        return ["/pong"]

    def on_message(self, topic: str, msg: Num) -> None:
        self.seen.append(msg.value)

    def finished(self) -> bool:
        return self.rounds in self.seen

    def passed(self) -> bool:
        return self.seen == list(range(1, self.rounds + 1))

    def render(self) -> str:
        return f"pongs {self.seen}"


def pong_report(scenario: Scenario) -> PongReport:
    """Report factory: the rounds come from the ping node's parameters."""
    return PongReport(scenario.node("ping").params.rounds)


@pytest.mark.slow
@pytest.mark.fleet
@pytest.mark.timeout(90)
@pytest.mark.parametrize("record", [False, True], ids=["private-file", "beside-the-event-log"])
def test_a_python_scenario_runs_live(tmp_path: Path, record: bool) -> None:
    from tests.integration.itest_support import fleet_nodes, poll
    from twinfleet.runtime.fleet.fleet_result import EndReason
    from twinfleet.runtime.fleet.launcher import LaunchOptions, format_result, run_fleet

    scenario = Scenario.build("pypong", [NodeEntry("ping", Ping, {"rounds": 3}),
                                         NodeEntry("pong", Pong)],
                              live={"report": f"{__name__}:pong_report"})
    private_dirs = set(Path(tempfile.gettempdir()).glob("twinfleet-scenario-*"))
    events = str(tmp_path / "events.jsonl") if record else None
    out = io.StringIO()
    result = asyncio.run(asyncio.wait_for(
        run_fleet(scenario, LaunchOptions(timeout_s=60, handle_signals=False,
                                          record_events=events), out=out),
        80))
    text = out.getvalue() + "\n".join(format_result(result))
    assert result.reason == "the run report says the run is finished", text
    assert result.end is EndReason.REPORT_FINISHED
    assert result.passed and result.report.seen == [1, 2, 3], text
    assert not result.failed, text
    # The node processes loaded a file written for them: a private one is gone afterwards;
    # one beside an event log stays, named by the log, so `twinfleet validate` can use it.
    assert set(Path(tempfile.gettempdir()).glob("twinfleet-scenario-*")) == private_dirs
    if events is not None:
        header = json.loads(Path(events).read_text().splitlines()[0])
        assert header["scenario"] == f"{events}.scenario.yaml"
        assert load_scenario(header["scenario"]).node("ping").params == PingParams(rounds=3)
    assert poll(lambda: not fleet_nodes(), 5)
