"""The relaxed-order search (`checker.cluster.flow`) gives the strict BFS's states,
transitions and verdicts, whatever order its messages arrive in.

The workers are `FlowCore`s stepped in this process (`LocalFlow`) on a system built from
the `SystemSpec` as a worker builds it, their claims and answers delivered in an order
shuffled by a seed; the coordinator hands them the search at `min_width`, once they say
they are up (some levels later: real workers take a while to start).
"""

from __future__ import annotations

from itertools import islice
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, assume, event, given, settings
from hypothesis import strategies as st

from tests.checker.program_systems import systems, write_scenario
from twinfleet.checker import CheckOptions, check
from twinfleet.checker.cluster import relaxed
from twinfleet.checker.cluster.coordinator import Coordinator
from twinfleet.checker.cluster.flow import LocalFlow
from twinfleet.checker.cluster.relaxed import DUMP_STATES
from twinfleet.checker.cluster.spec import SystemSpec
from twinfleet.checker.outcome import Limits, Outcome
from twinfleet.checker.properties import PropertySet
from twinfleet.checker.system import System
from twinfleet.runtime.scenario.overrides import load


def _relaxed(path: Path, workers: int, seed: int, max_states: int,
             late: int = 0) -> tuple[Outcome, LocalFlow]:
    scenario = load(str(path))
    props = PropertySet.from_scenario(scenario)
    system = System(scenario, properties=props)
    system_there, props_there, _ = SystemSpec(str(path), None, None, (), ()).build()
    flow = LocalFlow(system_there, props_there, workers, seed=seed, late=late)

    def no_levels(width: int) -> Any:
        raise AssertionError("a relaxed order runs no level on the cluster")

    coordinator = Coordinator(system, props, Limits(max_states=max_states), no_levels,
                              min_width=2, flow=lambda width: flow)
    return coordinator.run(), flow


@settings(max_examples=150, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(doc=systems(), workers=st.integers(2, 3), seed=st.integers(0, 2**16),
       late=st.integers(0, 3))
@pytest.mark.slow
def test_any_delivery_order_keeps_the_bfs_answers(tmp_path: Path, doc: dict[str, Any],
                                                  workers: int, seed: int, late: int) -> None:
    path = write_scenario(doc, tmp_path / "generated.yaml")
    one = check(path, CheckOptions(reduction="none", max_states=2_000))
    assume(one.status.value != "unknown")
    outcome, flow = _relaxed(path, workers, seed, 10**6, late)
    event("handed to the workers" if any(s.new for s in flow.status()) else "stayed home")
    assert outcome.status == one.status, (outcome.reason, one.reason)
    if one.violation is None:
        assert (outcome.statistics.states, outcome.statistics.transitions) == \
            (one.statistics.states, one.statistics.transitions)
        assert outcome.statistics.depth >= one.statistics.depth  # paths as found, not shortest
    else:
        assert outcome.violation is not None and outcome.counterexample is not None
        assert one.trace is not None
        assert len(outcome.counterexample.steps) >= len(one.trace["steps"])
        # Another order can meet another violated property first: it must be violated too.
        name = outcome.violation.property
        if name != one.violation.property:
            doc["properties"] = [p for p in doc["properties"] if p["name"] == name]
            alone = write_scenario(doc, tmp_path / "alone.yaml")
            assert check(alone, CheckOptions(reduction="none")).status.value == "violated"


@pytest.mark.slow
def test_a_shipped_case_keeps_its_counts_and_its_liveness_verdict(tmp_path: Path) -> None:
    from twinfleet.cli import main as cli

    cli(["examples", "--copy", "c1a", str(tmp_path)])
    path = tmp_path / "c1a.yaml"
    one = check(path, CheckOptions(reduction="none"))
    outcome, flow = _relaxed(path, 2, 7, 10**6)
    assert outcome.status == one.status and one.status.value == "holds"
    assert (outcome.statistics.states, outcome.statistics.transitions) == \
        (one.statistics.states, one.statistics.transitions)
    statuses = flow.status()
    assert all(s.new > 1_000 for s in statuses), "both workers kept worlds"
    assert sum(s.sent for s in statuses) == sum(s.received for s in statuses)


@pytest.mark.parametrize("dump_states", [0, DUMP_STATES], ids=["by-lineages", "dumped"])
def test_a_violation_found_in_a_relaxed_order_is_a_path_of_the_system(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, dump_states: int) -> None:
    from twinfleet.cli import main as cli

    monkeypatch.setattr(relaxed, "DUMP_STATES", dump_states)
    cli(["examples", "--copy", "headon", str(tmp_path)])
    path = tmp_path / "headon.yaml"
    one = check(path, CheckOptions(reduction="none"))
    outcome, _ = _relaxed(path, 3, 1, 10**6)
    assert outcome.status == one.status and outcome.violation is not None
    assert one.violation is not None and outcome.violation.property == one.violation.property
    assert outcome.counterexample is not None  # `Coordinator._path` ran it again step by step


def test_a_worker_takes_its_batch_as_it_expands_and_a_question_gets_half_the_rest(
        tmp_path: Path) -> None:
    from twinfleet.checker.cluster.flow import FlowCore
    from twinfleet.cli import main as cli

    cli(["examples", "--copy", "c1a", str(tmp_path)])
    system, props, _ = SystemSpec(str(tmp_path / "c1a.yaml"), None, None, (), ()).build()
    core = FlowCore(system, props, 0, 2, batch=8)
    world = next(iter(system.initial())).world
    core.queue.extend((world, key, 0) for key in range(20))
    batch = core.next_batch()
    assert [key for _, key, _ in islice(batch, 2)] == [0, 1], "the oldest first"
    assert len(core.queue) == 18, "taken one by one"
    assert [key for _, key, _ in core.spare()] == list(range(19, 10, -1)), "half the rest"
    assert [key for _, key, _ in batch] == list(range(2, 8)), "no more than a batch"
    core.queue.clear()
    core.queue.extend((world, key, 0) for key in range(3))
    assert [key for _, key, _ in core.next_batch()] == [0, 1, 2], "a short queue whole"
