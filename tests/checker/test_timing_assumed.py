"""`check --statistical` draws from the scenario's `check.latency` unless `--timing` is
given, and says first which model replaced the scenario's timing when it has none; every
summary, exhaustive included, states the timing it assumed (issue 37, finding 4)."""

from __future__ import annotations

import json

import pytest
import yaml

from tests.checker.tpc import tpc_scenario
from twinfleet.cli import main

pytestmark = pytest.mark.timeout(120)

SIMULATE = ["--statistical", "--simulations", "128", "--seed", "3", "--max-traces", "0"]


def _counts(record: dict) -> list[tuple[str, int]]:
    return [(e["property"], e["violations"]) for e in record["estimates"]]


def test_statistical_draws_from_the_scenarios_latency(tmp_path, capsys):
    path = tpc_scenario(tmp_path, decision_timeout_ms=3, latency=(0, 2))
    assert main(["check", str(path), *SIMULATE, "--json"]) == 1
    record = json.loads(capsys.readouterr().out)
    assert record["timing"] == {"latency": {"default": [0, 2]}, "timer_lateness": [0, 0],
                                "source": "the scenario's check.latency"}
    assert record["timing_replaced"] is None
    uniform = tmp_path / "uniform.timing.yaml"  # the same latency as a timing model file
    uniform.write_text(yaml.safe_dump({
        "format": "twinfleet-timing/1",
        "latency": {"default": {"values": [0, 1, 2], "weights": [1 / 3, 1 / 3, 1 / 3]}}}))
    assert main(["check", str(path), *SIMULATE, "--json", "--timing", str(uniform)]) == 1
    given = json.loads(capsys.readouterr().out)
    assert _counts(given) == _counts(record)
    assert given["timing"]["source"] == f"--timing {uniform}"


def test_a_model_replacing_the_scenarios_timing_is_said_first(tmp_path, capsys):
    path = tpc_scenario(tmp_path, latency=None)
    main(["check", str(path), *SIMULATE, "--quiet"])
    first = capsys.readouterr().out.splitlines()[0]
    assert first.startswith("timing: the loopback model shipped with twinfleet "
                            "(loopback.timing.yaml) replaces the scenario's timing"), first


def test_every_exhaustive_summary_states_the_timing_it_assumed(tmp_path, capsys):
    path = tpc_scenario(tmp_path, latency=(0, 2))
    assert main(["check", str(path), "--quiet"]) == 0
    assert ("timing: latency 0-2 ms, timers 0 ms late; from the scenario's check.latency, "
            "every value a branch") in capsys.readouterr().out.splitlines()
    bare = tpc_scenario(tmp_path, "bare", latency=None)
    assert main(["check", str(bare), "--json"]) == 0
    timing = json.loads(capsys.readouterr().out)["timing"]
    assert timing["latency"] == {"default": [0, 0]} and timing["timer_lateness"] == [0, 0]
    assert "sets no check.latency" in timing["source"]


def test_the_statistical_text_summary_states_the_latency_per_channel_and_its_source(tmp_path,
                                                                                  capsys):
    path = tpc_scenario(tmp_path, decision_timeout_ms=3, latency=None)
    doc = yaml.safe_load(path.read_text())
    doc["check"] = {"latency": {"default": [0, 2], "/vote": [1, 3]}}
    path.write_text(yaml.safe_dump(doc))
    main(["check", str(path), *SIMULATE, "--quiet"])
    assert ("  assumed: latency 0-2 ms (/vote 1-3 ms), timers 0 ms late; from the scenario's "
            "check.latency") in capsys.readouterr().out.splitlines()
