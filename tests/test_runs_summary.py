"""`launch --runs N` ends with one line that keeps an inconclusive run apart from a failed one
(a loaded machine's stalls are not collisions)."""

from __future__ import annotations

from twinfleet.runtime.fleet.fleet_result import runs_summary


def test_inconclusive_runs_are_not_counted_as_failed():
    assert runs_summary("c2a", [0, 3, 1, 3, 1], 5) == (
        "c2a: 1/5 passed, 2/5 failed, 2/5 inconclusive")
    assert runs_summary("c2a", [1, 1], 2) == "c2a: 0/2 passed, 2/2 failed"
    assert runs_summary("c1a", [0, 130], 3) == (
        "c1a: 1/3 passed, 0/3 failed, 1/3 ended otherwise, 1/3 not run")
