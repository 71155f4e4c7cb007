"""`check --statistical` draws from the scenario's `check.latency` unless `--timing` is
given, and says first which model replaced the scenario's timing when it has none; every
summary, exhaustive included, states the timing it assumed; an exhaustive check takes a
timing model's bounds, its timers' lateness included."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from tests.checker.tpc import tpc_scenario
from twinfleet.checker.cluster.spec import SystemSpec
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


SETTLED = Path(__file__).resolve().parents[1] / "data" / "station" / "settled.yaml"


def _late_timers(tmp_path: Path, late_ms: int) -> Path:
    """A timing model: every message due when sent, an `@every` tick on time or `late_ms`
    ms late (half and half)."""
    path = tmp_path / f"late{late_ms}.timing.yaml"
    values = sorted({0, late_ms})
    path.write_text(yaml.safe_dump({
        "format": "twinfleet-timing/1",
        "latency": {"default": {"values": [0], "weights": [1]}},
        "timer_lateness": {"values": values, "weights": [1 / len(values)] * len(values)}}))
    return path


def test_an_exhaustive_check_branches_on_the_timing_models_timer_lateness(tmp_path, capsys):
    assert main(["check", str(SETTLED), "--json", "--timing", str(_late_timers(tmp_path, 0))]) == 0
    on_time = json.loads(capsys.readouterr().out)
    assert main(["check", str(SETTLED), "--json", "--timing", str(_late_timers(tmp_path, 250))]) == 0
    late = json.loads(capsys.readouterr().out)
    assert on_time["timing"]["timer_lateness"] == [0, 0]
    assert late["timing"]["timer_lateness"] == [0, 250]
    # a tick two periods (100 ms) late or more skips ticks: each choice is a branch
    assert late["states"] > on_time["states"]


def test_a_cluster_builds_the_timing_models_timer_lateness_too(tmp_path):
    spec = SystemSpec(str(SETTLED), None, (), (), None, (("timer_lateness", (0, 250)),))
    system, _, _ = spec.build()
    assert system.settings.timer_lateness == (0, 250)
