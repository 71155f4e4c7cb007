"""One code path reads parameter overrides: every mode of `check`, `sweep` and `validate`
counts an override on the command line as the same value written in the file, and refuses
an unknown name with exit 2 and a "did you mean"; a misspelt key of the file's own common
`params:` is refused too (issue 37, findings 1 and 2)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from tests.checker.tpc import tpc_scenario
from twinfleet.cli import main

pytestmark = pytest.mark.timeout(120)

STATISTICAL = ["--statistical", "--simulations", "64", "--seed", "7", "--json",
               "--max-traces", "0"]


def _json(capsys: pytest.CaptureFixture[str]) -> dict:
    return json.loads(capsys.readouterr().out)


def _counts(record: dict) -> list[tuple[str, int]]:
    if "estimates" in record:
        return [(e["property"], e["violations"]) for e in record["estimates"]]
    return [("verdict", record["verdict"]), ("states", record["states"]),
            ("transitions", record["transitions"])]


@pytest.mark.parametrize("mode", [
    pytest.param([], id="exhaustive"),
    pytest.param(["--workers", "2", "--min-width", "1"], id="exhaustive-workers",
                 marks=[pytest.mark.ray, pytest.mark.slow]),
    pytest.param(STATISTICAL, id="statistical"),
    pytest.param([*STATISTICAL, "--workers", "2"], id="statistical-workers",
                 marks=pytest.mark.slow)])
def test_an_override_counts_as_the_value_in_the_file(tmp_path, capsys, mode):
    default = tpc_scenario(tmp_path, "default")
    written = tpc_scenario(tmp_path, "written", decision_timeout_ms=1)
    if "--json" not in mode:
        mode = [*mode, "--json"]
    assert main(["check", str(written), *mode]) == 1
    in_file = _counts(_json(capsys))
    assert main(["check", str(default), "decision_timeout_ms:=1", *mode]) == 1
    assert _counts(_json(capsys)) == in_file
    if "--min-width" in mode:
        return  # each check starts a Ray cluster (13 s): the other forms are the same words
    assert main(["check", str(default), "--param", "p1.decision_timeout_ms=1",
                 "--param", "p2.decision_timeout_ms=1", *mode]) == 1
    assert _counts(_json(capsys)) == in_file
    main(["check", str(default), *mode])
    assert _counts(_json(capsys)) != in_file  # the override changes the answer


@pytest.mark.parametrize("mode", [[], ["--workers", "2"], ["--statistical"],
                                  ["--statistical", "--workers", "2"], ["--strict"]])
@pytest.mark.parametrize(("word", "says"), [
    ("vote_timout_ms:=1", "did you mean 'vote_timeout_ms'?"),
    ("p1.decison_timeout_ms:=1", "did you mean 'decision_timeout_ms'?"),
    ("cord.decision_timeout_ms:=1", "did you mean 'coord'?"),
])
def test_an_unknown_override_is_exit_2_with_did_you_mean_in_every_mode(
        tmp_path, capsys, mode, word, says):
    path = tpc_scenario(tmp_path)
    assert main(["check", str(path), word, *mode]) == 2
    err = capsys.readouterr().err.strip()
    assert says in err and len(err.splitlines()) == 1, err


def test_sweep_refuses_an_unknown_name_with_did_you_mean(tmp_path, capsys):
    path = tpc_scenario(tmp_path)
    assert main(["sweep", str(path), "--param", "vote_timout_ms=1,2",
                 "--out", str(tmp_path / "sweep")]) == 2
    assert "did you mean 'vote_timeout_ms'?" in capsys.readouterr().err


@pytest.mark.parametrize("mode", [[], ["--statistical"], ["--strict"]])
def test_a_misspelt_common_param_in_the_file_is_exit_2_with_did_you_mean(tmp_path, capsys,
                                                                          mode):
    path = tpc_scenario(tmp_path, decison_timeout_ms=4)
    assert main(["check", str(path), *mode]) == 2
    err = capsys.readouterr().err.strip()
    assert "params.decison_timeout_ms: no node of the scenario declares this parameter" in err
    assert err.endswith("did you mean 'decision_timeout_ms'?") and len(err.splitlines()) == 1


def test_launch_refuses_a_misspelt_common_param_before_starting(tmp_path, capsys):
    path = tpc_scenario(tmp_path, decison_timeout_ms=4)
    assert main(["launch", str(path)]) == 2
    assert "did you mean 'decision_timeout_ms'?" in capsys.readouterr().err


def test_a_statistical_trace_records_its_overrides_and_replays_with_them(tmp_path, capsys):
    path = tpc_scenario(tmp_path)
    out = tmp_path / "traces"
    assert main(["check", str(path), "decision_timeout_ms:=1", "--statistical", "--simulations",
                 "64", "--seed", "7", "--json", "--traces-out", str(out)]) == 1
    traces = _json(capsys)["traces"]
    assert traces and json.loads(Path(traces[0]).read_text())["params"] == ["decision_timeout_ms:=1"]
    assert main(["replay", traces[0]]) == 1
    assert "replay confirmed" in capsys.readouterr().out


@pytest.mark.slow
def test_experiment_checks_with_the_overrides_and_refuses_unknown_ones(tmp_path, capsys):
    out = tmp_path / "exp"
    common = ["--runs", "0", "--predict", "0", "--semantics", "ros", "--out", str(out)]
    assert main(["experiment", "c1a", "r1.speed:=0.4", *common]) == 0
    report = json.loads((out / "experiment.json").read_text())
    assert report["options"]["params"] == ["r1.speed:=0.4"]
    row = report["scenarios"]["c1a"]["row"]
    assert row["parameters"].startswith(".4/")  # r1's speed, 0.5 in the file
    capsys.readouterr()
    assert main(["check", "c1a", "r1.speed:=0.4", "--semantics", "ros", "--json"]) == 0
    assert row["ros_states"] == _json(capsys)["states"]
    assert main(["experiment", "c1a", "r1.sped:=0.4", *common]) == 2
    assert "did you mean 'speed'?" in capsys.readouterr().err


def test_an_override_after_the_options_counts_too(tmp_path, capsys):
    default = tpc_scenario(tmp_path, "default")
    assert main(["check", str(default), "decision_timeout_ms:=1", *STATISTICAL]) == 1
    before = _counts(_json(capsys))
    assert main(["check", str(default), *STATISTICAL, "decision_timeout_ms:=1"]) == 1
    assert _counts(_json(capsys)) == before
    assert main(["check", str(default), "--quiet", "vote_timout_ms:=1"]) == 2
    assert "did you mean 'vote_timeout_ms'?" in capsys.readouterr().err


@pytest.mark.parametrize(("edit", "says"), [
    ({"paramz": {}}, "paramz: unknown key; expected one of"),
    ({"check": {"latncy": [0, 2]}}, "check.latncy: unknown key"),
    ({"live": {"timeout": 1}}, "live.timeout: unknown key"),
])
def test_every_misspelt_key_of_the_file_says_did_you_mean(tmp_path, capsys, edit, says):
    path = tpc_scenario(tmp_path)
    doc = yaml.safe_load(path.read_text())
    doc.update(edit)
    path.write_text(yaml.safe_dump(doc))
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err
    assert says in err and "; did you mean '" in err, err
