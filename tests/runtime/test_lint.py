"""Load-time lint (twinfleet/runtime/scenario/lint.py): risky imports, and names nothing answers."""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

import pytest

from twinfleet import Context, Node, String, on_start, service, subscribe
from twinfleet.runtime.scenario.examples import shipped_scenarios
from twinfleet.runtime.scenario.lint import lint_scenario, syntax_nodes
from twinfleet.runtime.scenario.spec import NodeEntry, Scenario, load_scenario

pytestmark = pytest.mark.timeout(60)
TALLY = 0


@dataclass
class Count:
    """How many messages arrived."""

    n: int = 0


class Typist(Node):
    """Publishes on /entr, meaning /enter; calls a service nobody serves."""

    @on_start
    def begin(self, ctx: Context) -> None:
        ctx.publish("/entr", String("r1"))
        ctx.call("/is_fre", String("c"), self.on_reply)

    def on_reply(self, ctx: Context, reply: object) -> None:
        global TALLY
        TALLY += 1


class Door(Node):
    """Subscribes to /enter, serves /is_free."""

    def initial_state(self) -> Count:
        return Count()

    @subscribe("/enter")
    def on_enter(self, ctx: Context, msg: String) -> None:
        self.state.n += 1

    @service("/is_free")
    def is_free(self, ctx: Context, req: String) -> String:
        return String("yes")


def _warnings(*entries: NodeEntry) -> list[str]:
    return [str(w) for w in lint_scenario(Scenario.build("lint", list(entries)))]


def test_a_typo_in_a_topic_is_warned_about_both_ways_with_a_suggestion():
    warnings = _warnings(NodeEntry("typist", Typist), NodeEntry("door", Door))
    published = [w for w in warnings if "publishes on /entr" in w]
    assert len(published) == 1 and "did you mean /enter?" in published[0]
    assert __file__ in published[0]  # file and line of the publish call
    assert any("node door: subscribes to /enter but no node publishes on it" in w
               for w in warnings)
    assert any("calls service /is_fre but no node serves it (did you mean /is_free?)" in w
               for w in warnings)
    assert any("`global TALLY`" in w for w in warnings)


class Right(Node):
    """Publishes on /enter, as meant."""

    @on_start
    def begin(self, ctx: Context) -> None:
        ctx.publish("/enter", String("r1"))


class Corrected(Typist):
    """Typist with the typo fixed in an override: the base's publish is not used."""

    @on_start
    def begin(self, ctx: Context) -> None:
        ctx.publish("/enter", String("r1"))


def test_an_overridden_method_is_not_read():
    warnings = _warnings(NodeEntry("fixed", Corrected), NodeEntry("door", Door))
    assert not [w for w in warnings if "/entr " in w or "/is_fre " in w]


def test_matching_names_give_no_topic_warnings():
    warnings = _warnings(NodeEntry("right", Right), NodeEntry("door", Door))
    assert not [w for w in warnings if "/enter" in w]


@pytest.mark.parametrize("name", sorted(shipped_scenarios()))
def test_shipped_scenarios_are_silent(name):
    assert lint_scenario(load_scenario(name)) == []


@pytest.mark.slow
@pytest.mark.fleet
def test_launch_prints_the_warnings_before_the_fleet_starts(tmp_path):
    import subprocess
    import sys

    import yaml

    from tests.support import ROOT, child_env

    path = tmp_path / "mistake.yaml"
    path.write_text(yaml.safe_dump({"name": "mistake", "nodes": [
        {"name": "n1", "class": "tests.checker.mistakes:Pinger"},
        {"name": "n2", "class": "tests.checker.mistakes:Hello"}]}))
    run = subprocess.run([sys.executable, "-m", "twinfleet", "launch", str(path), "--timeout",
                          "0.5"], cwd=ROOT, env=child_env(), capture_output=True, text=True,
                         timeout=60)
    warnings = [line for line in run.stderr.splitlines() if line.startswith("warning:")]
    assert any("mistakes.py:" in w and "imports random" in w for w in warnings), run.stderr
    assert "Traceback" not in run.stderr


def test_syntax_nodes_are_ast_walks_nodes_in_its_order():
    root = Path(__file__).resolve().parents[2] / "twinfleet"
    for path in sorted(root.rglob("*.py"))[:200]:
        tree = ast.parse(path.read_text())
        assert [id(n) for n in syntax_nodes(tree)] == [id(n) for n in ast.walk(tree)], path
