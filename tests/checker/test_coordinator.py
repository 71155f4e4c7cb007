"""The distributed search's coordinator, moving between itself and a cluster, gives the
one process's answers.

The cluster here is a `LocalBackend` (the cores the Ray actors run) on a system
built from the `SystemSpec` as a worker builds it, so the coordinator's moves
are tested without Ray: out to the
cluster when the frontier reaches `min_width` and the cluster says it is up (some
levels later, as real workers take a while to start), back when it falls below
`back_width`, again and again on generated systems, reduced or not, with
`eventually` properties decided on the gathered graph and reduced searches
restarting.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from tests.checker.program_systems import systems, write_scenario
from twinfleet.checker import CheckOptions, check
from twinfleet.checker.cluster import backend
from twinfleet.checker.cluster.backend import Checkpointing, LocalBackend
from twinfleet.checker.cluster.coordinator import Coordinator
from twinfleet.checker.cluster.level import Item
from twinfleet.checker.cluster.spec import SystemSpec
from twinfleet.checker.outcome import Guard, Limits, Stop
from twinfleet.checker.properties import PropertySet
from twinfleet.checker.reduction import plan
from twinfleet.checker.system import System
from twinfleet.runtime.contract.kinds import Status
from twinfleet.runtime.scenario.overrides import load


class CountingCluster:
    """A `LocalBackend` on a system built from the `SystemSpec`, as a worker builds it on
    another machine (the cluster's part of the cores), counting the coordinator's moves."""

    def __init__(self, spec: SystemSpec, late: int = 0) -> None:
        self.inner = LocalBackend(*spec.build())
        self.loads = self.takes = 0
        self.late = late  # polls of `ready` that say no: workers still starting

    def ready(self) -> bool:
        self.late -= 1
        return self.late < 0

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)

    def load(self, *args: Any) -> None:
        self.loads += 1
        self.inner.load(*args)

    def take_back(self) -> tuple[list[Item], list[bytes]]:
        self.takes += 1
        return self.inner.take_back()


def _coordinated(path: Path, reduction: str, max_states: int,
                 late: int = 0, reduce_from: int = 0) -> tuple[Any, CountingCluster]:
    scenario = load(str(path))
    props = PropertySet.from_scenario(scenario)
    system = System(scenario, properties=props)
    reduced, name = plan(system, props, "bfs", reduction, reduce_from)
    spec = SystemSpec(str(path), None, None, (), (),
                      reduction=None if reduced is None else name.split()[0])
    cluster = CountingCluster(spec, late)
    coordinator = Coordinator(system, props, Limits(max_states=max_states),
                              lambda width: cluster, min_width=3, reduction=reduced,
                              back_width=2, patience=1)
    return coordinator.run(), cluster


@settings(max_examples=150, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@pytest.mark.slow
@given(doc=systems(), reduction=st.sampled_from(["none", "por"]), late=st.integers(0, 3),
       reduce_from=st.sampled_from([0, 40]))
def test_moving_out_and_back_keeps_the_one_process_answers(tmp_path: Path, doc: dict[str, Any],
                                                            reduction: str, late: int,
                                                            reduce_from: int) -> None:
    # (reduce_from 40: por starts late, `checker.late_start`, in both searches alike)
    path = write_scenario(doc, tmp_path / "generated.yaml")
    one = check(path, CheckOptions(reduction=reduction, max_states=2_000,
                                   reduce_from=reduce_from))
    assume(one.status.value != "unknown")
    outcome, cluster = _coordinated(path, reduction, 2_000, late, reduce_from)
    assert outcome.status == one.status, (outcome.reason, one.reason)
    if one.violation is None:
        assert (outcome.statistics.states, outcome.statistics.transitions,
                outcome.statistics.depth) == (one.statistics.states, one.statistics.transitions,
                                              one.statistics.depth)
    else:
        assert outcome.violation is not None
        assert outcome.violation.property == one.violation.property
        assert outcome.counterexample is not None and one.trace is not None
        assert len(outcome.counterexample.steps) == len(one.trace["steps"])


def test_a_wide_then_narrow_search_moves_both_ways(tmp_path: Path) -> None:
    from twinfleet.cli import main as cli

    cli(["examples", "--copy", "headon", str(tmp_path)])
    path = tmp_path / "headon.yaml"
    one = check(path, CheckOptions(reduction="none"))
    outcome, cluster = _coordinated(path, "none", 10**6)
    assert cluster.loads >= 2 and cluster.takes >= 1, (cluster.loads, cluster.takes)
    assert outcome.status == one.status and one.trace is not None
    assert outcome.counterexample is not None
    assert len(outcome.counterexample.steps) == len(one.trace["steps"])


def _headon(tmp_path: Path) -> tuple[System, PropertySet]:
    from twinfleet.cli import main as cli

    cli(["examples", "--copy", "headon", str(tmp_path)])
    scenario = load(str(tmp_path / "headon.yaml"))
    props = PropertySet.from_scenario(scenario)
    return System(scenario, properties=props), props


def test_a_level_searched_here_ticks_within_itself_unless_checkpointed(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # `--max-time` and Ctrl-C are seen inside a level the coordinator searches itself (a
    # wide level takes seconds there), not only between levels; a search that saves
    # checkpoints keeps ticking between levels only (a stop mid-level saves nothing whole).
    system, props = _headon(tmp_path)
    monkeypatch.setattr(backend, "TICK_WORLDS", 4)
    ticks: list[int] = []
    monkeypatch.setattr(Guard, "tick", lambda self, statistics: ticks.append(1))
    within = Coordinator(system, props, Limits(), None, min_width=10**9).run()
    ticked_within = len(ticks)
    ticks.clear()
    plan_ = Checkpointing(str(tmp_path / "c.ckpt"), 3600.0, {})
    between = Coordinator(system, props, Limits(), None, min_width=10**9,
                          checkpointing=plan_).run()
    assert within.status == between.status
    assert within.statistics.states == between.statistics.states
    assert len(ticks) <= between.statistics.depth + 2 < ticked_within
    assert ticked_within >= within.statistics.states // 4


def test_a_stop_inside_a_level_ends_the_search_unknown(tmp_path: Path,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    system, props = _headon(tmp_path)
    monkeypatch.setattr(backend, "TICK_WORLDS", 1)
    full = Coordinator(system, props, Limits(), None, min_width=10**9).run()
    calls: list[int] = []

    def tick(self: Guard, statistics: Any) -> None:
        calls.append(1)
        if len(calls) == full.statistics.states // 2:
            raise Stop("max-time 1 s reached before the search finished")

    monkeypatch.setattr(Guard, "tick", tick)
    outcome = Coordinator(system, props, Limits(), None, min_width=10**9).run()
    assert outcome.status is Status.UNKNOWN and "max-time" in outcome.reason
    assert outcome.statistics.states < full.statistics.states
