"""A viewer (and a recording) left open follows a fleet launched again on the same endpoint.

Each launch gives the fleet new credentials (README "Trust model"); the viewer's
session, opened with the first run's read-only login, kept reconnecting with it
and never saw the second run. Two short runs of a three-walker fleet, one after
the other, under one `twinfleet view`: the page state must count both runs'
samples and show the second run's trails from their start cells again.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest
from viewer_support import ROOT, api, child_env, free_port, get_json, poll, printed_url

pytestmark = [pytest.mark.slow, pytest.mark.timeout(90)]

STEPS = 15  # stamps up to 1.5 s: the second run going back to 0.1 s is a new run
WALKERS = '''
from dataclasses import dataclass

from twinfleet import Context, Node, every
from twinfleet.nodes.msgs import RobotPose


@dataclass(frozen=True)
class WalkerParams:
    row: int = 0


@dataclass
class WalkerState:
    col: int = 0


class Walker(Node):
    """Steps along its row and reports its pose; stops after {steps} steps."""

    Params = WalkerParams

    def initial_state(self) -> WalkerState:
        return WalkerState()

    @every(100)
    def step(self, ctx: Context) -> None:
        if self.state.col < {steps}:
            self.state.col += 1
            ctx.publish("/poses", RobotPose(self.name, (self.params.row, self.state.col), 2, 1))
'''


def _launch(scenario: Path, endpoint: str) -> None:
    done = subprocess.run([sys.executable, "-m", "twinfleet", "launch", str(scenario),
                           "--listen", endpoint], capture_output=True, text=True,
                          env=child_env(), cwd=ROOT, timeout=60, check=False)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]


def test_a_viewer_follows_the_fleet_launched_again(cli, tmp_path):
    (tmp_path / "walkers.py").write_text(WALKERS.format(steps=STEPS))
    scenario = tmp_path / "walk.yaml"
    # the walkers publish the robot case's poses: the robot scene draws them
    scenario.write_text("name: walk\nscene: twinfleet.nodes.scene:RobotScene\nnodes:\n" + "".join(
        f'  - {{name: w{i}, class: "walkers:Walker", params: {{row: {i}}}}}\n'
        for i in (1, 2, 3)) + "live: {wall_timeout_s: 3}\n")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    port = free_port()
    viewer = cli("view", "--port", str(port), "--connect", endpoint, "--fleet", "walk",
                 log="viewer.log")
    url = api(printed_url(viewer.log), "api/state")
    poll(lambda: get_json(url), 15, "the viewer's HTTP server")
    for run in (1, 2):
        _launch(scenario, endpoint)
        deadline = time.monotonic() + 20
        while (seen := _poses(get_json(url))) != 3 * STEPS * run:
            state = get_json(url) or {}
            assert time.monotonic() < deadline, (
                f"run {run}: the viewer counted {seen} poses, not {3 * STEPS * run}; link "
                f"{state.get('link')}, trails {_trails(state)}")
            time.sleep(0.1)
    assert _trails(get_json(url)) == {f"w{i}": [[c + 0.5, i + 0.5] for c in range(1, STEPS + 1)]
                                      for i in (1, 2, 3)}  # cells (i, c) by their centres


def _poses(state: dict | None) -> int | None:
    return (state or {}).get("topics", {}).get("/poses", {}).get("count")


def _trails(state: dict) -> dict[str, list]:
    return {name: robot["trail"]["items"] for name, robot in state.get("robots", {}).items()}


def test_a_recording_follows_the_fleet_launched_again(cli, tmp_path):
    import msgpack
    from mcap.reader import make_reader

    (tmp_path / "walkers.py").write_text(WALKERS.format(steps=STEPS))
    scenario = tmp_path / "walk.yaml"
    scenario.write_text("name: walk\nnodes:\n" + "".join(
        f'  - {{name: w{i}, class: "walkers:Walker", params: {{row: {i}}}}}\n'
        for i in (1, 2, 3)) + "live: {wall_timeout_s: 3}\n")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    first = cli("launch", str(scenario), "--listen", endpoint, log="first.log")
    poll(lambda: first.log.read_text().count("started") >= 3, 30, "the first run's nodes")
    out = tmp_path / "both.mcap"
    recorder = cli("record", "--connect", endpoint, "--fleet", "walk", "-o", str(out),
                   log="record.log")
    poll(lambda: first.poll() is not None, 30, "the first run's end")
    _launch(scenario, endpoint)  # new credentials, same endpoint
    recorder.send_signal(2)
    recorder.wait(timeout=20)
    assert "wrote" in recorder.log.read_text(), recorder.log.read_text()
    stamps = []
    with out.open("rb") as f:
        for _schema, channel, message in make_reader(f).iter_messages(log_time_order=True):
            if channel.topic == "/poses":
                stamps.append(msgpack.unpackb(message.data)["stamp_ms"])
    restart = max(i for i in range(1, len(stamps)) if stamps[i] < stamps[i - 1] - 500)
    second = stamps[restart:]
    # The recorder can log in only once the second run's credentials exist, so that run's
    # first poses may pass before it has reconnected (longer on a loaded machine); from then
    # on it must miss nothing and follow the run to its end.
    first_step = min(second) // 100
    assert first_step <= STEPS // 2, stamps
    assert len(second) >= 3 * (STEPS - first_step + 1) - 2, stamps
    assert second.count(STEPS * 100) == 3, stamps
