"""Honest verdicts (docs/design.md §5): a run whose nodes dropped samples a verdict
depends on, or whose node stalled behind its timers, is INCONCLUSIVE (exit 3) with the reason,
never PASSED. Each test starts its own fleet on loopback with bounded traffic."""

from __future__ import annotations

import os
import re
import signal
import time

import pytest

from tests.adversarial.fleets import (
    expect,
    launched,
    robot_scenario,
    run_launch,
    wait_for_line,
    write_scenario,
)
from tests.integration.itest_support import node_pid, poll, spawned_by

pytestmark = [pytest.mark.slow, pytest.mark.timeout(90)]


def test_a_bounded_flood_that_makes_a_node_drop_samples_is_inconclusive(tmp_path):
    # 3 bursts of 3000 messages, 100 ms apart, at a subscriber that needs every one
    # (RELIABLE) but lets only 5 wait: it must drop some, and the run must say so.
    nodes = [{"name": "flooder", "class": "Flooder", "params": {"burst": 3000, "bursts": 3}},
             {"name": "sink", "class": "Sink"}]
    path = write_scenario(tmp_path, "flood", nodes, [
        {"name": "counts", "kind": "invariant", "expr": "sink.count >= 0"}])
    out = expect(run_launch(path, "--timeout", "3"), 3, "result: INCONCLUSIVE (")
    lines = out.splitlines()
    at = next(i for i, line in enumerate(lines) if "result: INCONCLUSIVE (" in line)
    # the drops are a reason: on the result line, or, when the flooder also fell behind
    # its timers on a loaded machine and that reason came first, on a reason line below it
    reasons = [lines[at]] + [line for line in lines[at + 1:] if line.startswith("[launcher]   ")]
    assert any("sink dropped" in line for line in reasons), out[-3000:]
    assert "PASSED" not in out


def test_the_same_fleet_without_the_flood_passes(tmp_path):
    nodes = [{"name": "flooder", "class": "Flooder", "params": {"burst": 1, "bursts": 3}},
             {"name": "sink", "class": "Sink"}]
    path = write_scenario(tmp_path, "trickle", nodes, [
        {"name": "counts", "kind": "invariant", "expr": "sink.count >= 0"}])
    expect(run_launch(path, "--timeout", "2"), 0, "result: PASSED")


ROBOTS = {"r2": {"start": [5, 15], "goal": [45, 35], "speed": 0.7, "max_wait_ms": 2000},
          "r3": {"start": [5, 25], "goal": [45, 25], "speed": 0.8, "max_wait_ms": 2500}}


def test_a_robot_stopped_and_continued_stalls_and_the_run_is_inconclusive(tmp_path):
    path = robot_scenario(tmp_path, ROBOTS)
    seen: list[str] = []
    with launched(path, "--time-scale", "4", "--timeout", "40") as proc:
        assert wait_for_line(proc, "[r2] t=", seen), "".join(seen)  # r2 started
        pids = [node_pid(spawned_by(proc.pid), "r2")]
        assert pids[0] is not None
        time.sleep(0.5)  # r2 is on its way
        os.kill(pids[0], signal.SIGSTOP)
        try:
            time.sleep(1.5)  # 6 s of fleet time: dozens of scan periods
        finally:
            os.kill(pids[0], signal.SIGCONT)
        rest, _ = proc.communicate(timeout=60)
    out = "".join(seen) + rest
    assert proc.returncode == 3, out[-3000:]
    # the stall is a reason (beside the samples the depth-10 queues of r2 and of the map
    # server may drop meanwhile)
    assert "result: INCONCLUSIVE (" in out, out[-2500:]
    assert re.search(r"r2 fell behind its timers by up to \d+ ms .*: it stalled\)", out), out[-2500:]
    assert poll(lambda: not spawned_by(proc.pid), 10)
