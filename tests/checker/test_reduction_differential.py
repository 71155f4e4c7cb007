"""Differential tests on generated node systems.

Hypothesis draws small random systems of program nodes
(`tests/checker/program_systems.py`) and checks each several ways that must
agree. Today: breadth-first and depth-first search give the same verdict,
the same state and transition counts when every property holds (both visit
the whole reachable graph), BFS's safety counterexample is never longer than
DFS's, and every counterexample trace replays and violates its property
(`twinfleet.checker.replay`). The partial-order reduction adds "reduced ==
unreduced" on the same systems: `outcome()` below is the one place a search
runs, so that test only passes other options.

A search that reaches `MAX_STATES` proves nothing about the system, so that
example is discarded with `assume` (it shows as "limit hit" in
`--hypothesis-show-statistics`); it is rare by construction (measured: 0-2 %
of examples; about 3 % of the systems have a zero-time cycle, 95 % at most 100
states). Derandomized, so CI runs the same examples: 300 systems (and 100
crowded ones) for the reduction, 100 for BFS against DFS, 30 for
the transition cache (about 100 s of CPU on the 2-core VM); a longer random run:

    TWINFLEET_DIFFERENTIAL_EXAMPLES=3000 TWINFLEET_DIFFERENTIAL_RANDOM=1 \\
        python3 -m pytest -q tests/checker/test_reduction_differential.py \\
        --hypothesis-show-statistics
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, assume, event, given, settings
from hypothesis import strategies as st

from tests.checker.helpers import replay_confirms
from tests.checker.program_systems import systems, write_scenario
from twinfleet.checker import CheckOptions, CheckResult, check
from twinfleet.runtime.contract.kinds import Status

MAX_STATES = 3_000
EXAMPLES = int(os.environ.get("TWINFLEET_DIFFERENTIAL_EXAMPLES", "300"))
DIFFERENTIAL = settings(max_examples=EXAMPLES, deadline=None,
                        derandomize=not os.environ.get("TWINFLEET_DIFFERENTIAL_RANDOM"),
                        suppress_health_check=[HealthCheck.too_slow],
                        print_blob=True)


@dataclass(frozen=True)
class Outcome:
    """What one search concluded, in the terms the differential tests compare."""

    status: str
    property: str | None
    shape: str | None
    states: int
    transitions: int
    steps: int | None
    result: CheckResult

    @property
    def safety(self) -> bool:
        """True for a violation found on a path or terminal world (not a lasso search)."""
        return self.status is Status.VIOLATED and self.result.violation is not None and \
            self.result.violation.kind not in ("eventually",)


def outcome(path: Path, **options: Any) -> Outcome:
    """Check `path` with `options` (CheckOptions fields); discard the example at the state limit."""
    options.setdefault("trace_out", str(path.with_suffix(f".{options.get('search', 'bfs')}.json")))
    result = check(path, CheckOptions(max_states=MAX_STATES, **options))
    if result.status is Status.UNKNOWN:
        event("limit hit")
        assume(False)
    v = result.violation
    s = result.statistics
    return Outcome(result.status, v.property if v else None, v.shape if v else None,
                   s.states, s.transitions, len(result.trace["steps"]) if result.trace else None,
                   result)


@pytest.fixture(scope="module")
def workdir() -> Iterator[Path]:
    """One directory for every generated scenario of this module (examples overwrite it)."""
    with tempfile.TemporaryDirectory(prefix="twinfleet-differential-") as tmp:
        yield Path(tmp)


def _size_event(states: int) -> None:
    bucket = next(b for b in (10, 100, 1_000, MAX_STATES) if states <= b)
    event(f"states <= {bucket:,}")


@pytest.mark.slow
@settings(DIFFERENTIAL, max_examples=max(1, EXAMPLES // 3))  # the older check: 100 in CI
@given(doc=systems())
def test_bfs_and_dfs_agree_and_counterexamples_replay(workdir: Path, doc: dict[str, Any]) -> None:
    path = write_scenario(doc, workdir / "system.yaml")
    # the full graph: reduced BFS and DFS graphs differ (the cycle proviso depends on the order)
    bfs = outcome(path, search="bfs", reduction="none")
    dfs = outcome(path, search="dfs", reduction="none")
    _size_event(bfs.states)
    event(f"verdict {bfs.status}")
    assert bfs.status == dfs.status
    if bfs.status is Status.HOLDS:
        assert (bfs.states, bfs.transitions) == (dfs.states, dfs.transitions)
        return
    if bfs.safety and dfs.safety:
        # BFS stops at the first violating world or transition it meets, in depth order.
        assert bfs.steps is not None and dfs.steps is not None
        assert bfs.steps <= dfs.steps
    for found in (bfs, dfs):
        assert replay_confirms(found.result), found.result.summary()


@pytest.mark.slow
@settings(DIFFERENTIAL, max_examples=max(1, EXAMPLES // 10))
@given(doc=systems(), search=st.sampled_from(["bfs", "dfs"]))
def test_transition_cache_changes_nothing(workdir: Path, doc: dict[str, Any], search: str) -> None:
    # The cache reuses handler outcomes by (node state, event, time): what the reduction,
    # which reads transitions' effects, relies on. With and without it the search (reduced
    # under ros, by default) is the same.
    path = write_scenario(doc, workdir / "system.yaml")
    cached = outcome(path, search=search)
    fresh = outcome(path, search=search, transition_cache=False)
    assert (cached.status, cached.property, cached.states, cached.transitions, cached.steps) == \
        (fresh.status, fresh.property, fresh.states, fresh.transitions, fresh.steps)


@pytest.mark.slow  # about 22 s for 300 systems on the 2-core VM: CI runs it, the fast path not
@pytest.mark.timeout(600)
@DIFFERENTIAL
@given(doc=systems(), search=st.sampled_from(["bfs", "dfs"]))
def test_reduction_keeps_the_verdict_and_its_counterexamples_replay(
        workdir: Path, doc: dict[str, Any], search: str) -> None:
    # The partial-order reduction on every generated system, asked for explicitly
    # (under rebeca it is off by default): the same verdict as the full search; a reduced
    # search visits a subset of the reachable worlds; its counterexamples replay and violate.
    _reduced_equals_full(workdir, doc, search)


@pytest.mark.slow  # about 15 s for 100 systems
@pytest.mark.timeout(600)
@settings(DIFFERENTIAL, max_examples=max(1, EXAMPLES // 3))
@given(doc=systems(crowded=True), search=st.sampled_from(["bfs", "dfs"]))
def test_declared_commutation_keeps_the_verdict(workdir: Path, doc: dict[str, Any],
                                                search: str) -> None:
    # Systems where every node's start publishes on /bus and n1's /bus handler is declared
    # commutes=True (`tests/checker/program_nodes.CommutingProgramNode`): the reduction takes
    # one order of the messages that meet there, checking each pair it relies on.
    _reduced_equals_full(workdir, doc, search)


def _reduced_equals_full(workdir: Path, doc: dict[str, Any], search: str) -> None:
    path = write_scenario(doc, workdir / "system.yaml")
    full = outcome(path, search=search, reduction="none")
    reduced = outcome(path, search=search, reduction="por",
                      trace_out=str(path.with_suffix(f".{search}.por.json")))
    ran = reduced.result.reduction.split(" ")[0]
    event(f"reduction {ran}" if ran == "por" else f"reduction {reduced.result.reduction}")
    assert full.result.reduction == "none"
    assert reduced.status == full.status, (reduced.result.summary(), full.result.summary())
    stats = reduced.result.reduction_statistics or {}
    for name in ("commuted", "refuted", "rises"):
        if stats.get(name):
            event(f"reduction relied on {name}")
    if "goals not rising" in reduced.result.reduction:
        event("a goal fell")
    if ran == "por" and reduced.status is Status.HOLDS:
        event("fewer states" if reduced.states < full.states else "as many states")
        assert reduced.states <= full.states
    if reduced.status is Status.VIOLATED:
        assert replay_confirms(reduced.result), reduced.result.summary()
