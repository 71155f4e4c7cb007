"""A distributed search saved to a checkpoint continues on any number of workers.

The coordinator saves between two levels (where the search is consistent):
the visited set of every shard and the frontier of every worker in one file.
Resumed on 3 workers, on 2, or in this process, the search ends with the
counts or the counterexample length of a search never stopped. Ctrl-C stops
it between levels with a checkpoint written; a shard killed after a save
ends the command with no verdict and names the file to resume.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from tests.cluster.test_distributed import assert_same_answer, assert_same_reduction, safety_copy
from tests.support import child_env
from tests.support import wait_for_line as _wait_for
from twinfleet.checker import CheckOptions, check
from twinfleet.checker.checkpoint import CheckpointError
from twinfleet.checker.cluster import engine_module

pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def engine() -> Any:
    """A local Ray cluster of 3 workers on 127.0.0.1 for the module."""
    engine = engine_module()
    with engine.session(3, None):
        yield engine


def _stopped_on_two_workers(path: Path, checkpoint: Path, reduction: str = "none",
                            **limits: Any) -> None:
    first = check(path, CheckOptions(reduction=reduction, workers=2, cluster="this",
                                     min_width=1, checkpoint=str(checkpoint), **limits))
    assert first.status.value == "unknown" and "max-states" in first.reason, first.reason
    assert (first.engine or "").startswith("strict BFS on 2 Ray worker(s)"), first.engine
    assert first.checkpoint == str(checkpoint) and checkpoint.is_file()


@pytest.mark.usefixtures("engine")
@pytest.mark.parametrize("reduction", ["none", "por"])
def test_a_holding_search_resumes_on_three_workers_and_in_one_process(tmp_path: Path,
                                                                      reduction: str) -> None:
    path = safety_copy("headon", tmp_path, latency={"default": [0, 1]})
    one = check(path, CheckOptions(reduction=reduction, max_depth=80))
    saved = tmp_path / "search.ckpt"
    _stopped_on_two_workers(path, saved, reduction, max_depth=80, max_states=3_000)
    copy = tmp_path / "copy.ckpt"
    shutil.copy(saved, copy)
    on_three = check(None, CheckOptions(resume=str(saved), workers=3, cluster="this",
                                        min_width=1, max_depth=80))
    assert (on_three.engine or "").startswith("strict BFS on 3 Ray worker(s)"), on_three.engine
    here = check(None, CheckOptions(resume=str(copy), max_depth=80))
    assert (here.engine or "").startswith("strict BFS in one process"), here.engine
    for resumed in (on_three, here):
        assert resumed.resumed_from is not None
        assert resumed.reason == one.reason
        assert (resumed.statistics.states, resumed.statistics.transitions,
                resumed.statistics.depth) == (one.statistics.states, one.statistics.transitions,
                                              one.statistics.depth)
        assert_same_reduction(one, resumed)


@pytest.mark.usefixtures("engine")
def test_a_violated_search_resumed_finds_a_trace_as_short(tmp_path: Path) -> None:
    path = safety_copy("headon", tmp_path, latency={"default": [0, 1]})
    one = check(path, CheckOptions(reduction="none"))
    assert one.violation is not None
    saved = tmp_path / "search.ckpt"
    _stopped_on_two_workers(path, saved, max_states=5_000)
    resumed = check(None, CheckOptions(resume=str(saved), workers=2, cluster="this",
                                       min_width=1))
    assert_same_answer(one, resumed)


def test_a_checkpoint_of_one_process_is_not_resumed_on_workers(tmp_path: Path) -> None:
    path = safety_copy("headon", tmp_path, latency={"default": [0, 1]})
    saved = tmp_path / "single.ckpt"
    check(path, CheckOptions(reduction="none", max_states=1_000, checkpoint=str(saved)))
    with pytest.raises(CheckpointError, match="written by the search in one process"):
        check(None, CheckOptions(resume=str(saved), workers=2))


def _check_process(*args: str) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-m", "twinfleet", "check", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=child_env(), cwd=ROOT, start_new_session=True)


def test_ctrl_c_stops_between_levels_with_a_checkpoint_that_resumes(tmp_path: Path) -> None:
    path = safety_copy("c1a", tmp_path, latency={"default": [0, 1]})
    saved = tmp_path / "c1a.ckpt"
    proc = _check_process(str(path), "--reduction", "none", "--workers", "2", "--min-width", "1",
                          "--checkpoint", str(saved))
    try:
        _wait_for(proc, "states/s per worker")  # a level done on the cluster
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=120)
    finally:
        with contextlib.suppress(ProcessLookupError):
            proc.kill()
    assert "UNKNOWN: interrupted (Ctrl-C)" in out, (out, err)
    assert f"checkpoint: {saved}" in out and saved.is_file()
    states = _states(out)
    resumed = subprocess.run([sys.executable, "-m", "twinfleet", "check", "--resume", str(saved),
                              "--workers", "2", "--min-width", "1", "--max-states",
                              str(states + 2_000)], capture_output=True, text=True,
                             env=child_env(), cwd=ROOT, timeout=300, check=False)
    assert f"resumed from checkpoint {saved}" in resumed.stdout, resumed
    assert "max-states" in resumed.stdout and _states(resumed.stdout) >= states + 2_000


def _states(summary: str) -> int:
    line = next(x for x in summary.splitlines() if x.startswith("states "))
    return int(line.split()[1].replace(",", ""))


def test_a_shard_killed_after_a_save_names_the_checkpoint(tmp_path: Path) -> None:
    from tests.cluster.test_cluster_faults import _pid_named

    path = safety_copy("c1a", tmp_path, latency={"default": [0, 1]})
    saved = tmp_path / "c1a.ckpt"
    proc = _check_process(str(path), "--reduction", "none", "--workers", "2", "--min-width", "1",
                          "--checkpoint", str(saved), "--checkpoint-every", "0")
    try:
        _wait_for(proc, "states/s per worker")
        deadline = time.monotonic() + 60
        while not saved.is_file() and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.05)  # saved at the end of the level the line reported
        assert saved.is_file()
        shard = _pid_named(b"ray::Shard", proc.pid)
        assert shard is not None
        with contextlib.suppress(ProcessLookupError):
            os.kill(shard, signal.SIGKILL)
        out, err = proc.communicate(timeout=120)
    finally:
        with contextlib.suppress(ProcessLookupError):
            proc.kill()
    assert proc.returncode == 2, (out, err)
    assert "no verdict" in err and f"twinfleet check --resume {saved}" in err, err
    assert "verdict:" not in out
