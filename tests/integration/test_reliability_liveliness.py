"""Live faults: a node killed mid-run is noticed via liveliness, respawned, and reported.

The fleet runs in-process through `run_fleet` (real node processes, real Zenoh on
127.0.0.1), with an output stream that stamps every line as the launcher writes
it, so time-to-detect is measured from the SIGKILL to the moment the watcher's
"lost" line reaches the launcher (an upper bound of the watcher's own delay).
"""

from __future__ import annotations

import asyncio
import dataclasses
import io
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import zenoh
from itest_support import (
    ROOT,
    child_env,
    fleet_nodes,
    kill_all,
    node_pid,
    pick_free_port,
    poll,
    spawned_by,
)

from twinfleet.runtime.access.fleetauth import login_settings, registry_auth
from twinfleet.runtime.contract.messages import String, encode
from twinfleet.runtime.core.guard import sign
from twinfleet.runtime.fleet.launcher import SHUTDOWN_TOPIC, LaunchOptions, format_result, run_fleet
from twinfleet.runtime.fleet.run_record import read_run_record
from twinfleet.runtime.host.keys import topic_key
from twinfleet.runtime.host.zenoh_transport import zenoh_config
from twinfleet.runtime.scenario.spec import load_scenario

pytestmark = [pytest.mark.slow, pytest.mark.timeout(90)]

NODES = "tests.integration.reliability_nodes"
SCENARIO = f"""\
name: faults
seed: 4
nodes:
  - {{name: watcher, class: "{NODES}:Watcher", params: {{watch: [r1, r2]}}}}
  - {{name: r1, class: "{NODES}:Heartbeat", respawn: true, params: {{period_ms: 100}}}}
  - {{name: r2, class: "{NODES}:Heartbeat", params: {{period_ms: 100}}}}
live: {{summary_topics: [/fleet_status]}}
"""


class StampedLines(io.TextIOBase):
    """A text sink that keeps each line with the monotonic time it was written."""

    def __init__(self) -> None:
        self.lines: list[tuple[float, str]] = []
        self._partial = ""

    def write(self, text: str) -> int:
        now = time.monotonic()
        self._partial += text
        *complete, self._partial = self._partial.split("\n")
        self.lines.extend((now, line) for line in complete)
        return len(text)

    def text(self) -> str:
        return "\n".join(line for _, line in self.lines)

    async def wait_for(self, pattern: str, *, after: float = 0.0, timeout: float = 20.0) -> float:
        """Time of the first line matching `pattern` written after `after`."""
        regex = re.compile(pattern)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for stamp, line in self.lines:
                if stamp >= after and regex.search(line):
                    return stamp
            await asyncio.sleep(0.005)
        raise AssertionError(f"no line matching {pattern!r} within {timeout} s:\n{self.text()}")


def request_shutdown(endpoint: str, fleet: str) -> None:
    """Publish on the launcher's shutdown topic from a plain session, with the fleet's
    operator login and key from its registry entry (an unsigned request is ignored)."""
    auth = registry_auth(endpoint)
    with zenoh.open(zenoh_config(connect=[endpoint],
                                 settings=login_settings(auth, write=True))) as session:
        key = topic_key(fleet, SHUTDOWN_TOPIC)
        pub = session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
        deadline = time.monotonic() + 5
        while not pub.matching_status.matching and time.monotonic() < deadline:
            time.sleep(0.01)
        payload = encode(String("test done"), sender="test")
        pub.put(payload, attachment=sign(auth.key, key, payload) if auth.key else None)
        time.sleep(0.2)
        pub.undeclare()


def test_killed_node_is_detected_within_a_second_respawned_and_reported(tmp_path: Path) -> None:
    path = tmp_path / "faults.yaml"
    path.write_text(SCENARIO)
    scenario = load_scenario(path)
    endpoint = f"tcp/127.0.0.1:{pick_free_port()}"
    record = tmp_path / "run.jsonl"
    out = StampedLines()
    figures: dict[str, float] = {}

    async def body() -> object:
        options = LaunchOptions(time_scale=1.0, timeout_s=60, seed=4, listen=endpoint,
                                handle_signals=False, run_record=str(record))
        run = asyncio.create_task(run_fleet(scenario, options, out=out))
        try:
            await out.wait_for(r"\[watcher\] t=\d+ alive node='r1'", timeout=30)
            await out.wait_for(r"\[watcher\] t=\d+ alive node='r2'", timeout=30)
            await out.wait_for(r"\[r1\] t=-?\d+ started", timeout=30)
            for round_ in (1, 2):  # twice: the respawned process is watched like the first
                pid = node_pid(fleet_nodes(), "r1")
                assert pid is not None, out.text()
                killed = time.monotonic()
                os.kill(pid, signal.SIGKILL)
                lost = await out.wait_for(r"\[watcher\] t=\d+ lost node='r1'", after=killed)
                back = await out.wait_for(r"\[watcher\] t=\d+ back node='r1'", after=lost)
                figures[f"detect_{round_}_s"] = lost - killed
                figures[f"back_{round_}_s"] = back - killed
            figures["shutdown_at"] = time.monotonic()
            await asyncio.to_thread(request_shutdown, endpoint, scenario.fleet)
            return await asyncio.wait_for(run, 30)
        finally:
            if not run.done():
                run.cancel()
                await asyncio.gather(run, return_exceptions=True)

    try:
        result = asyncio.run(body())
    finally:
        kill_all(fleet_nodes())
    shutdown_at = figures.pop("shutdown_at")
    print("\nliveliness figures:", json.dumps({k: round(v, 3) for k, v in figures.items()}))
    assert figures["detect_1_s"] < 1.0 and figures["detect_2_s"] < 1.0, figures
    # r2 was never killed: until the shutdown (when every node stops, in any order) it stays up.
    before_shutdown = "\n".join(line for stamp, line in out.lines if stamp < shutdown_at)
    assert "lost node='r2'" not in before_shutdown
    assert result.restarts == {"watcher": 0, "r1": 2, "r2": 0}  # type: ignore[attr-defined]
    assert result.reason == "shutdown requested by test: test done"  # type: ignore[attr-defined]
    summary = format_result(result)  # type: ignore[arg-type]
    # each node's line, then the counters that are not zero
    assert any(line.startswith("  r1: exit code 0 (ok, restarts 2)") for line in summary), summary
    assert any(line.startswith("  r2: exit code 0 (ok)") for line in summary), summary
    # the watcher's last status: r1's two losses, plus any node that stopped before the watcher
    # did at the shutdown (nodes stop in any order then)
    alive, lost, losses = dataclasses.astuple(result.last_messages["/fleet_status"])  # type: ignore[attr-defined]
    assert sorted((*alive, *lost)) == ["r1", "r2"] and losses == 2 + len(lost), (alive, lost, losses)
    assert "[launcher] node r1 exited with code -9" in out.text()

    events = read_run_record(record)
    kinds = [e["event"] for e in events]
    assert kinds[0] == "start" and kinds[-1] == "summary", kinds
    assert [e["code"] for e in events if e["event"] == "node_exit"] == [-9, -9]
    assert [e["restart"] for e in events if e["event"] == "respawn"] == [1, 2]
    end = next(e for e in events if e["event"] == "end")
    assert end["reason"] == "shutdown requested by test: test done"
    stats = next(e for e in events if e["event"] == "node_stats")["stats"]
    assert set(stats) == {"watcher", "r1", "r2"}
    assert stats["watcher"]["received"] > 0 and stats["watcher"]["gaps"] == 0
    last = events[-1]
    assert last["restarts"] == {"watcher": 0, "r1": 2, "r2": 0} and last["ok"] is True
    assert events[0]["versions"]["eclipse-zenoh"] != "not installed"
    assert not fleet_nodes()


LAUNCH_SCRIPT = """
import asyncio, sys
from twinfleet.runtime.fleet.launcher import LaunchOptions, run_fleet
from twinfleet.runtime.scenario.spec import load_scenario
asyncio.run(run_fleet(load_scenario(sys.argv[1]),
                      LaunchOptions(run_record=sys.argv[2], listen=sys.argv[3])))
"""


def test_the_run_record_survives_a_killed_launcher_and_no_node_outlives_it(tmp_path: Path) -> None:
    path = tmp_path / "crash.yaml"
    path.write_text(f"""\
name: crash
nodes:
  - {{name: r1, class: "{NODES}:Heartbeat", respawn: true}}
""")
    record = tmp_path / "crash.jsonl"
    launcher = subprocess.Popen([sys.executable, "-c", LAUNCH_SCRIPT, str(path), str(record),
                                 f"tcp/127.0.0.1:{pick_free_port()}"], cwd=ROOT,
                                env=child_env(), stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
    try:
        assert poll(lambda: node_pid(spawned_by(launcher.pid), "r1") is not None, 30)
        first = node_pid(spawned_by(launcher.pid), "r1")
        os.kill(first, signal.SIGKILL)  # type: ignore[arg-type]
        assert poll(lambda: any(e["event"] == "respawn" for e in read_run_record(record)), 20)
        assert poll(lambda: node_pid(spawned_by(launcher.pid), "r1") not in (None, first), 20)
        launcher.kill()
        launcher.wait(timeout=10)
        assert poll(lambda: not spawned_by(launcher.pid), 10), spawned_by(launcher.pid)
    finally:
        if launcher.poll() is None:
            launcher.kill()
            launcher.wait(timeout=10)
        kill_all(spawned_by(launcher.pid))
    text = record.read_text()
    assert text.endswith("\n")  # every line was complete when the launcher died
    events = read_run_record(record)
    assert [e["event"] for e in events] == ["start", "node_exit", "respawn"]
    assert events[0]["scenario"] == str(path) and events[1]["code"] == -9
