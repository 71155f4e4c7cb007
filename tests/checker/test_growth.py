"""The state-growth diagnosis: a search stopped by a limit names the node field that never
repeats (in the summary, --json and the progress line); a bounded one is not named."""

from __future__ import annotations

import json

import pytest

from tests.checker.helpers import run, scenario
from twinfleet.checker.commands import _progress, main
from twinfleet.runtime.contract.kinds import Status

pytestmark = pytest.mark.timeout(120)

G = "tests.checker.growth_models:"


def _one(tmp_path, cls, name):
    return scenario(tmp_path, [{"name": "r1", "class": G + cls}], name=name)


def test_a_counter_never_reset_is_named(tmp_path, capsys):
    result = run(_one(tmp_path, "Resetter", "resets"), max_states=3000)
    assert result.status is Status.UNKNOWN
    notes = result.growth_notes()
    assert [n.name for n in notes] == ["r1.resets"]
    assert notes[0].direction == 1 and notes[0].step == 1
    text = result.summary()
    assert "state growth: r1.resets took" in text and "grows by 1 a step" in text
    assert "--max-depth/within" in text
    assert "r1.phase" not in text  # it cycles through 4 values
    assert result.to_json()["growth"][0]["field"] == "resets"
    # the progress line is printed from the search's statistics, which carry the notes
    _progress(result.statistics)
    assert "growing: r1.resets (" in capsys.readouterr().err


def test_a_drifting_float_is_named(tmp_path):
    result = run(_one(tmp_path, "Drifter", "drift"), max_states=2500)
    assert result.status is Status.UNKNOWN
    names = [n.name for n in result.growth_notes()]
    assert "r1.heading" in names
    assert "len(r1.turns)" not in names


def test_a_bounded_counter_is_not_named(tmp_path):
    # the phase follows the counter: 100 states, then HOLDS
    done = run(_one(tmp_path, "BoundedResetter", "bounded"))
    assert done.status is Status.HOLDS
    assert done.growth_notes() == () and "state growth" not in done.summary()
    # beside a heading that drifts, stopped by a limit long after the counter took each of
    # its 100 values many times: only the heading still grows
    drifter = {"name": "r2", "class": G + "Drifter", "params": {"wobble": False}}
    stopped = run(scenario(tmp_path, [{"name": "r1", "class": G + "BoundedResetter"},
                                      drifter], name="mixed"), max_states=6000)
    assert stopped.status is Status.UNKNOWN
    names = [n.name for n in stopped.growth_notes()]
    assert "r2.heading" in names and "r1.resets" not in names


def test_cli_names_the_field_in_text_and_json(tmp_path, capsys):
    assert main(["check", str(_one(tmp_path, "Resetter", "cli")), "--max-time", "1",
                 "--quiet"]) == 2
    out = capsys.readouterr().out
    assert "UNKNOWN: max-time 1 s" in out and "state growth: r1.resets took" in out
    drift = _one(tmp_path, "Drifter", "json")
    assert main(["check", str(drift), "--max-states", "2500", "--json"]) == 2
    assert [g["field"] for g in json.loads(capsys.readouterr().out)["growth"]] == ["heading"]


def test_a_deep_search_stopped_with_nothing_named_gets_the_hint():
    # C1a reduced is one path of 5,516 worlds; its fields take a few dozen values each
    from twinfleet.checker.driver import CheckOptions, check

    result = check("c1a", CheckOptions(max_states=1500, trace_out=None, reduce_from=0))
    assert result.status is Status.UNKNOWN and result.statistics.depth >= 1000
    assert result.growth_notes() == ()
    assert "hint: the search was still going deeper (depth 1,4" in result.summary()
