"""How a statistical check runs its rounds: the next round is sent while one is still
running (several workers, a fixed count), and the simulator a process keeps for a job
lives as long as the check that made it."""

from __future__ import annotations

import threading
from collections.abc import Sequence
from pathlib import Path

import pytest

from tests.checker.test_statistical import _scenario
from twinfleet.checker import statistical
from twinfleet.checker.parallel import BatchFn, R
from twinfleet.checker.statistical import StatisticalOptions, check_statistical


class _Overlapping:
    """Two workers in this process: the first round's map waits (on an event, at most
    `wait_s`) until the second round has been sent, and says whether it was."""

    workers = 2

    def __init__(self, wait_s: float) -> None:
        self.wait_s = wait_s
        self.sent: list[int] = []  # each map's first index, in the order they were called
        self.second = threading.Event()
        self.overlapped: bool | None = None
        self.closed = False
        self._one = threading.Lock()  # one simulator here: one batch at a time

    def map(self, batch_fn: BatchFn[R], batches: Sequence[list[int]]) -> list[list[R]]:
        self.sent.append(batches[0][0])
        if len(self.sent) == 2:
            self.second.set()
        if len(self.sent) == 1:
            self.overlapped = self.second.wait(self.wait_s)
        with self._one:
            return [batch_fn(b) for b in batches]

    def close(self) -> None:
        self.closed = True


def _run(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, engine: _Overlapping,
         **options: object) -> statistical.StatisticalResult:
    monkeypatch.setattr(statistical, "engine_for", lambda workers, cluster=None: engine)
    path = _scenario(tmp_path)
    return check_statistical(path, StatisticalOptions(
        seed=11, workers=2, timing=str(tmp_path / "timing.yaml"),
        traces_out=str(tmp_path / "out"), max_traces=0, **options))  # type: ignore[arg-type]


def test_with_two_workers_the_next_round_is_sent_before_one_ends(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    engine = _Overlapping(wait_s=30)
    result = _run(tmp_path, monkeypatch, engine, simulations=3 * statistical.ROUND + 5)
    assert engine.overlapped is True
    assert engine.sent == [0, 64, 128, 192] and engine.closed
    assert [s.index for s in result.simulations] == list(range(3 * statistical.ROUND + 5))


def test_a_test_that_can_stop_any_round_sends_none_ahead(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    engine = _Overlapping(wait_s=0.2)  # nothing sets the event: it times out, as it should
    result = _run(tmp_path, monkeypatch, engine, assert_below=0.3, indifference=0.2,
                  alpha=0.05, beta=0.05)
    assert engine.overlapped is False
    assert result.sprt is not None and engine.sent[-1] < len(result.simulations)


def test_a_check_leaves_no_simulator_in_this_process(tmp_path: Path) -> None:
    path = _scenario(tmp_path)
    check_statistical(path, StatisticalOptions(
        simulations=10, seed=2, timing=str(tmp_path / "timing.yaml"),
        traces_out=str(tmp_path / "out"), max_traces=0))
    assert not statistical._HELD


def test_a_process_keeps_one_job_s_simulator_for_its_batches(tmp_path: Path) -> None:
    path = str(_scenario(tmp_path))
    model, _, _ = statistical.statistical_timing(statistical.load(path),
                                                 str(tmp_path / "timing.yaml"))
    jobs = [statistical.SimulationJob(path, None, model, seed, 1000, 100) for seed in (1, 2)]
    try:
        first = statistical._simulator(jobs[0])
        assert statistical._simulator(jobs[0]) is first  # its later batches reuse it
        assert jobs[0]([0, 1]) == [first.run(0), first.run(1)]
        second = statistical._simulator(jobs[1])
        assert second is not first and [j for j, _ in statistical._HELD] == [jobs[1]]
        statistical.release(jobs[0])  # another job's: kept
        assert statistical._HELD
    finally:
        statistical.release(jobs[1])
    assert not statistical._HELD
