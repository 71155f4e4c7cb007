"""A reduced breadth-first search that walks ahead once it is large (`Reduction.probe`)
keeps every verdict, restarts earlier, and the distributed search walks at the same level
with the same result."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import HealthCheck, assume, given, settings

from tests.checker.program_systems import systems, write_scenario
from tests.checker.test_coordinator import _coordinated
from twinfleet.checker import CheckOptions, check
from twinfleet.cli import main as cli


@settings(max_examples=60, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@pytest.mark.slow
@given(doc=systems())
def test_walking_ahead_keeps_the_verdict_and_the_coordinator_walks_alike(
        tmp_path: Path, doc: dict[str, Any]) -> None:
    path = write_scenario(doc, tmp_path / "generated.yaml")
    full = check(path, CheckOptions(reduction="none", max_states=2_000))
    assume(full.status.value != "unknown")
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr("twinfleet.checker.reduction.PROBE_STATES", 5)  # walk early
        patch.setattr("twinfleet.checker.reduction.PROBE_SHARE", 1)
        reduced = check(path, CheckOptions(reduction="por", max_states=2_000, reduce_from=0))
        outcome, _ = _coordinated(path, "por", 2_000)
    assert reduced.status == full.status, (reduced.reason, full.reason)
    assert outcome.status == reduced.status
    if reduced.violation is None:
        assert (outcome.statistics.states, outcome.statistics.transitions) == \
            (reduced.statistics.states, reduced.statistics.transitions)


@pytest.mark.slow
def test_a_send_met_deep_is_learned_before_the_search_gets_there(tmp_path: Path) -> None:
    # headon with 0-1 ms latencies: a BFS learns its sends level by level and restarts
    # each time; walking ahead learns most of them at once, for the same graph.
    cli(["examples", "--copy", "headon", str(tmp_path)])
    path = tmp_path / "headon.yaml"
    doc = yaml.safe_load(path.read_text())
    doc["properties"] = [p for p in doc["properties"] if p["kind"] != "eventually"]
    doc.setdefault("check", {})["latency"] = {"default": [0, 1]}
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    with pytest.MonkeyPatch.context() as patch:  # no walks at restarts either
        patch.setattr("twinfleet.checker.reduction.Reduction.walk_on", lambda *_: None)
        patch.setattr("twinfleet.checker.reduction.PROBE_STATES", 10**9)
        level_by_level = check(path, CheckOptions(reduce_from=0))
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr("twinfleet.checker.reduction.Reduction.walk_on", lambda *_: None)
        patch.setattr("twinfleet.checker.reduction.PROBE_STATES", 500)
        patch.setattr("twinfleet.checker.reduction.PROBE_SHARE", 1)
        ahead = check(path, CheckOptions(reduce_from=0))
    assert ahead.status == level_by_level.status
    assert ahead.statistics.states == level_by_level.statistics.states
    assert ahead.trace == level_by_level.trace

    def restarts(line: str | None) -> int:
        assert line is not None
        return int(line.split(" restarts")[0].rsplit(" ", 1)[1])

    assert "learned ahead by 2 walks" in (ahead.reduction or "")
    assert restarts(ahead.reduction) < restarts(level_by_level.reduction)
