"""`check` takes launch's parameter overrides; traces carry them, find their scenario after a
move, and say when it changed; a misspelt property field is refused at load."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
import yaml

from tests.checker.helpers import node, scenario
from twinfleet import testing
from twinfleet.checker import commands
from twinfleet.runtime.scenario.examples import shipped_scenarios

pytestmark = pytest.mark.timeout(60)

BELOW_3 = [{"name": "below_3", "kind": "invariant", "expr": "c.count < 3"}]


def _counter(tmp_path: Path, name: str = "count", **params: int) -> Path:
    return scenario(tmp_path, [node("c", "Counter", **params)], properties=BELOW_3, name=name)


def _json(capsys: pytest.CaptureFixture[str]) -> dict:
    return json.loads(capsys.readouterr().out)


@pytest.mark.slow
def test_check_c1a_with_an_override_counts_as_the_file_with_that_speed(tmp_path, capsys):
    assert commands.main(["c1a", "r1.speed:=0.4", "--json"]) == 0
    overridden = _json(capsys)
    doc = yaml.safe_load(shipped_scenarios()["c1a"].read_text())
    r1 = next(n for n in doc["nodes"] if n["name"] == "r1")
    assert r1["params"]["speed"] == 0.5  # the override changes something
    r1["params"]["speed"] = 0.4
    common = doc["params"]
    common["map"] = str((shipped_scenarios()["c1a"].parent / common["map"]).resolve())
    edited = tmp_path / "c1a_slow.yaml"
    edited.write_text(yaml.safe_dump(doc, sort_keys=False))
    assert commands.main([str(edited), "--json"]) == 0
    written = _json(capsys)
    assert overridden["params"] == ["r1.speed:=0.4"]
    assert (overridden["states"], overridden["transitions"]) == (
        written["states"], written["transitions"])
    assert commands.main(["c1a", "--json"]) == 0  # and the default speed counts otherwise
    assert _json(capsys)["states"] != written["states"]


@pytest.mark.parametrize(("words", "says"), [
    (["c.nosuch:=1"], "parameter override 'c.nosuch:=1': node 'c' has no parameter 'nosuch' "
                      "(it has: period_ms, modulo, cap)"),
    (["c.modul:=1"], "node 'c' has no parameter 'modul' (it has: period_ms, modulo, cap); did you mean 'modulo'?"),
    (["zz.modulo:=1"], "has no node 'zz'"),
    (["modulo"], "unexpected argument 'modulo'"),
    (["--param", "c.modulo"], "expected [NODE.]NAME=VALUE"),
    (["c.modulo:=[1"], "the value is not YAML"),
])
def test_a_bad_override_is_one_line_exit_2(tmp_path, capsys, words, says):
    path = _counter(tmp_path)
    assert commands.main([str(path), *words]) == 2
    err = capsys.readouterr().err
    assert says in err, err
    assert len(err.strip().splitlines()) == 1, err


def test_the_trace_records_the_overrides_and_replay_applies_them(tmp_path, capsys):
    path = _counter(tmp_path)  # modulo 3: count < 3 holds
    trace = tmp_path / "out" / "count.trace.json"
    assert commands.main([str(path), "--quiet", "--trace-out", str(trace)]) == 0
    assert commands.main([str(path), "c.modulo:=5", "--quiet", "--trace-out", str(trace)]) == 1
    assert "with c.modulo:=5" in capsys.readouterr().out
    written = json.loads(trace.read_text())
    assert written["params"] == ["c.modulo:=5"]
    assert commands.main(["replay", str(trace)]) == 1
    assert "replay confirmed" in capsys.readouterr().out
    written["params"] = []  # without them the violation is not there: replay applied them
    trace.write_text(json.dumps(written))
    assert commands.main(["replay", str(trace)]) == 2


def test_the_pytest_api_takes_the_same_overrides(tmp_path):
    path = _counter(tmp_path)
    assert testing.check(path).holds
    assert testing.check(path, params=["c.modulo:=5"]).violated
    with pytest.raises(Exception, match="has no node 'zz'"):
        testing.check(path, params=["zz.modulo:=5"])


def test_a_trace_replays_after_its_project_folder_moves(tmp_path, capsys):
    project = tmp_path / "project"
    project.mkdir()
    path = _counter(project, modulo=5)
    trace = project / "out" / "count.trace.json"
    assert commands.main([str(path), "--quiet", "--trace-out", str(trace)]) == 1
    capsys.readouterr()
    moved = shutil.move(str(project), str(tmp_path / "moved"))
    moved_trace = Path(moved) / "out" / "count.trace.json"
    assert commands.main(["replay", str(moved_trace)]) == 1
    captured = capsys.readouterr()
    assert "replay confirmed" in captured.out
    assert "changed" not in captured.err
    scenario_file = Path(moved) / path.name
    scenario_file.write_text(scenario_file.read_text() + "# edited\n")
    assert commands.main(["replay", str(moved_trace)]) == 1
    err = capsys.readouterr().err
    assert f"{scenario_file}: the scenario changed since the trace was written" in err


def test_a_misspelt_property_field_is_refused_at_load_listing_the_fields(tmp_path, capsys):
    path = scenario(tmp_path, [node("c", "Counter")], name="typo", properties=[
        {"name": "p", "kind": "eventually", "expr": "c.cont > 2"}])
    assert commands.main([str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert "property 'p': c.cont: the state of c (CountState) has no field 'cont'" in err
    assert err.endswith("its fields: count")
    indexed = scenario(tmp_path, [node("c", "Counter")], name="typo2", properties=[
        {"name": "p", "kind": "invariant", "expr": "nodes['c'].cont < 3"}])
    assert commands.main([str(indexed)]) == 2
    assert "has no field 'cont'" in capsys.readouterr().err
    shadowed = scenario(tmp_path, [node("c", "Counter")], name="ok", properties=[
        {"name": "p", "kind": "invariant", "expr": "all(c.real < 3 for c in [1j])"}])
    assert commands.main([str(shadowed), "--quiet"]) == 0  # a comprehension's c is not the node
