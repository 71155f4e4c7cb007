"""A message of a type its receiving handler does not take: one verdict in both drivers.

A station publishes `std_msgs/String` where the monitor's handler takes
`charging/StationStatus`. `twinfleet check` stops at the publish with exit 4;
`twinfleet launch` shows the same line once (not once per sample), counts the
samples and ends CONTRACT BREACH with that line, exit 4 too.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from tests.support import child_env

pytestmark = [pytest.mark.slow, pytest.mark.timeout(90)]

NODES = '''
from dataclasses import dataclass

from twinfleet import Context, Node, QoS, String, every, message, subscribe


@message("charging/StationStatus")
class StationStatus:
    in_use: int


@dataclass
class SeenState:
    seen: int = 0


class Station(Node):
    @every(100)
    def tick(self, ctx: Context) -> None:
        ctx.publish("/station_status", String("free"))


class Monitor(Node):
    def initial_state(self) -> SeenState:
        return SeenState()

    @subscribe("/station_status", qos=QoS(depth=1))
    def on_status(self, ctx: Context, msg: StationStatus) -> None:
        self.state.seen += msg.in_use
'''

SCENARIO = '''name: wrongtype
nodes:
  - {name: station, class: "charging.nodes:Station"}
  - {name: monitor, class: "charging.nodes:Monitor"}
live: {wall_timeout_s: 1.5}
'''

LINE = ("wrong message type: station published on /station_status std_msgs/String, but "
        "monitor.on_status takes charging/StationStatus")


def _twinfleet(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "twinfleet", *args], cwd=cwd, env=child_env(),
                          capture_output=True, text=True, timeout=60, check=False)


def test_a_wrong_type_is_one_breach_in_both_drivers(tmp_path: Path) -> None:
    (tmp_path / "charging").mkdir()
    (tmp_path / "charging" / "__init__.py").write_text("")
    (tmp_path / "charging" / "nodes.py").write_text(NODES)
    scenario = tmp_path / "wrong.yaml"
    scenario.write_text(SCENARIO)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()

    checked = _twinfleet("check", str(scenario), cwd=elsewhere)
    assert checked.returncode == 4, checked.stdout + checked.stderr
    assert LINE in checked.stderr and "handler tick" in checked.stderr, checked.stderr
    assert len(checked.stderr.strip().splitlines()) == 1, checked.stderr

    launched = _twinfleet("launch", str(scenario), cwd=elsewhere)
    out = launched.stdout + launched.stderr
    assert launched.returncode == 4, out
    shown = [line for line in out.splitlines() if LINE in line]
    # once from the monitor as it happens, once in the result line with the count
    assert len(shown) == 2, out
    assert shown[0].startswith("[monitor] wrong message type"), out
    result = next(line for line in out.splitlines() if "result:" in line)
    assert f"CONTRACT BREACH ({LINE}" in result and "samples)" in result, result
    assert "rejected sample" not in out, out
