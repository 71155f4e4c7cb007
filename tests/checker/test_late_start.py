"""The partial-order reduction starts late (`checker.late_start`): a `por` search stores its
first `REDUCE_FROM` worlds unreduced, then starts again reduced if a sample of its frontier
says the reduction pays, or goes on unreduced where it is if not.

Each test compares with the searches the late start stands between: the unreduced one
(`reduction="none"`) and the one reduced from the first world (`reduce_from=0`).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.checker.test_coordinator import _coordinated
from twinfleet.checker import CheckOptions, check
from twinfleet.checker.driver import CheckResult
from twinfleet.checker.options import REDUCE_FROM
from twinfleet.checker.search import Search

ROOT = Path(__file__).resolve().parents[2]
LAUNCH = ROOT / "twinfleet" / "launch"
TWO_PHASE = ROOT / "tests" / "data" / "two_phase" / "two_phase_small.yaml"
WAITED = ("none (por starts once a search stored 1,000 worlds: a smaller one costs more to "
          "reduce than to search; this one stored fewer)")


def counts(result: CheckResult) -> tuple[int, int, int]:
    return result.statistics.states, result.statistics.transitions, result.statistics.depth


def passes(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """The worlds stored when each pass of a `Search` began (a restart begins one)."""
    begun: list[int] = []
    monkeypatch.setattr(Search, "_explore", lambda self, f=Search._explore: (
        begun.append(len(self.store)), f(self))[1])
    return begun


@pytest.mark.parametrize("search", ["bfs", "dfs"])
def test_a_search_smaller_than_the_wait_is_the_unreduced_search(monkeypatch, search):
    # head-on: 399 worlds. Reduced from the first world it stores 284 in more time (the
    # closures and the walk ahead cost more than the 115 worlds they save).
    path = LAUNCH / "headon.yaml"
    full = check(path, CheckOptions(reduction="none", search=search))
    eager = check(path, CheckOptions(reduce_from=0, search=search))
    begun = passes(monkeypatch)
    late = check(path, CheckOptions(search=search))
    assert REDUCE_FROM == 1_000 and full.statistics.states < REDUCE_FROM
    assert counts(late) == counts(full) and late.trace == full.trace
    assert eager.statistics.states < full.statistics.states
    assert late.reduction == WAITED and begun == [0]
    assert late.reduction_statistics is not None
    assert late.reduction_statistics["reduced"] == late.reduction_statistics["full"] == 0


def test_a_search_that_gets_there_starts_again_reduced(monkeypatch):
    # C2c: 13,678 worlds unreduced, 733 reduced. It stores the first levels unreduced (1,539
    # worlds when a level starts past 1,000), then searches the graph reduced from scratch,
    # with the restart a search reduced from the first world has.
    path = LAUNCH / "c2c.yaml"
    eager = check(path, CheckOptions(reduce_from=0))
    begun = passes(monkeypatch)
    late = check(path, CheckOptions())
    assert late.status == eager.status == "violated"
    assert counts(late) == counts(eager) and late.trace == eager.trace
    stats = late.reduction_statistics
    assert stats is not None and stats["prefix"] >= REDUCE_FROM and stats["restarts"] == 1
    assert begun[:2] == [0, 0] and len(begun) == 2 + stats["restarts"]
    assert f"started after {stats['prefix']:,} worlds searched unreduced" in late.reduction
    assert late.reduction.startswith("por (persistent sets: 455 worlds reduced")


@pytest.mark.parametrize("search", ["bfs", "dfs"])
def test_a_reduction_that_would_not_pay_steps_aside_where_the_search_is(monkeypatch, search):
    # The small two-phase commit of tests/data (2,843 worlds): hardly a world of its frontier
    # has a persistent set smaller than everything. The search goes on unreduced from the
    # worlds it has: one pass, the unreduced search's counts, nothing searched twice.
    full = check(TWO_PHASE, CheckOptions(reduction="none", search=search))
    begun = passes(monkeypatch)
    late = check(TWO_PHASE, CheckOptions(search=search))
    assert counts(late) == counts(full) and begun == [0]
    assert late.reduction.startswith("none (por stepped aside: ")
    assert " worlds sampled after the first 1," in late.reduction
    assert late.reduction.endswith("would be reduced, under 20%; the search ran unreduced)")


def test_a_checkpoint_written_while_the_reduction_waits_resumes_waiting(tmp_path):
    # Stopped at 500 worlds, before the reduction started: resumed, the search goes on
    # unreduced, starts the reduction where the uninterrupted one does, and ends alike.
    path = LAUNCH / "c2c.yaml"
    saved = str(tmp_path / "search.ckpt")
    stopped = check(path, CheckOptions(max_states=500, checkpoint=saved))
    assert stopped.status == "unknown" and stopped.reduction == WAITED
    resumed = check(path, CheckOptions(resume=saved))
    whole = check(path, CheckOptions())
    assert resumed.status == whole.status and counts(resumed) == counts(whole)
    assert resumed.reduction == whole.reduction


@pytest.mark.parametrize(("path", "reduce_from", "moves"), [
    (LAUNCH / "c2c.yaml", REDUCE_FROM, False),  # starts again reduced (a narrow graph)
    (TWO_PHASE, REDUCE_FROM, True),  # steps aside in place, then out to the workers
    (LAUNCH / "headon.yaml", 200, True),  # starts after a few levels
])
def test_the_distributed_search_starts_as_the_one_process_search_does(path: Path,
                                                                     reduce_from: int,
                                                                     moves: bool):
    # The coordinator (its cluster a stand-in, out from 3 worlds wide) keeps the frontier
    # in this process while the reduction waits: it decides on the same sample.
    one = check(path, CheckOptions(reduce_from=reduce_from))
    outcome, cluster = _coordinated(path, "por", 10**6, reduce_from=reduce_from)
    assert outcome.status == one.status
    if one.violation is None:
        assert counts(one)[:2] == (outcome.statistics.states, outcome.statistics.transitions)
    else:
        assert outcome.counterexample is not None and one.trace is not None
        assert len(outcome.counterexample.steps) == len(one.trace["steps"])
    assert (cluster.loads >= 1) is moves
