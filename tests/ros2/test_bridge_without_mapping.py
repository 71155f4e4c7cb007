"""`launch --ros2` for a fleet of the test's own message types with no ROS 2 mapping written:
every message is carried by its fields, checked against zenoh-ros2-sdk (not ours) in its own
process, whose message definition is a `.msg` file written here by hand, through a plain Zenoh
router on 127.0.0.1 standing where rmw_zenohd would (multicast off). A bridge that never
reaches its router makes the run INCONCLUSIVE; a mapping that does not load is one line at
start, and one beside the scenario loads from any working directory."""

from __future__ import annotations

import json
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import yaml
import zenoh

from tests.integration.itest_support import kill_all, spawned_by
from tests.support import child_env, pick_free_port
from twinfleet.runtime.host.zenoh_transport import zenoh_config

pytestmark = [pytest.mark.slow, pytest.mark.fleet, pytest.mark.timeout(120)]

NODES = '''
from dataclasses import dataclass
from twinfleet import Context, Node, every, message

@message("turtle_msgs/Pose")
class Pose:
    x: float
    y: float
    theta: float
    name: str

@dataclass
class TurtleState:
    x: float = 0.0

class Turtle(Node):
    tool_topics = ("/pose",)

    def initial_state(self) -> TurtleState:
        return TurtleState()

    @every(100)
    def tick(self, ctx: Context) -> None:
        self.state.x += 0.5
        ctx.publish("/pose", Pose(self.state.x, 2.0, 0.25, self.name))
'''

MAPPING = '''
class Mapping:
    latched = frozenset()
    mapped_types = frozenset()

    def outbound(self, topic, type_name, data, stamp_ms):
        return ()
'''


def _fleet(folder: Path) -> Path:
    folder.mkdir()
    (folder / "turtle_nodes.py").write_text(NODES)
    (folder / "turtle_map.py").write_text(MAPPING)
    path = folder / "turtle.yaml"
    path.write_text(yaml.safe_dump({
        "name": "turtle", "nodes": [{"name": "turtle1", "class": "turtle_nodes:Turtle"}],
        "properties": [{"name": "moves", "kind": "eventually", "expr": "turtle1.x > 1"}]}))
    return path


def _launch(scenario: Path, cwd: Path, *args: str) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-m", "twinfleet", "launch", str(scenario), *args],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=child_env(), cwd=cwd)


def _stop(proc: subprocess.Popen[str]) -> str:
    """SIGINT the launcher, and end what it started and left behind."""
    started = spawned_by(proc.pid)
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    try:
        out, _ = proc.communicate(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate(timeout=5)
    kill_all(sorted(set(started) | set(spawned_by(proc.pid))))
    return out or ""


def test_a_fleet_of_its_own_types_is_on_ros2_with_no_mapping_written(tmp_path):
    scenario = _fleet(tmp_path / "turtle")
    msgs = tmp_path / "msgs" / "turtle_msgs" / "msg"
    msgs.mkdir(parents=True)
    (msgs / "Pose.msg").write_text("float64 x\nfloat64 y\nfloat64 theta\nstring name\n")
    port = pick_free_port()
    router = zenoh.open(zenoh_config(listen=[f"tcp/127.0.0.1:{port}"], mode="router"))
    launcher = _launch(scenario, tmp_path, "--ros2", "--ros2-router", f"tcp/127.0.0.1:{port}",
                       "--timeout", "60")
    lines: queue.Queue[str] = queue.Queue()
    assert launcher.stdout is not None
    reader = threading.Thread(target=lambda: [lines.put(x) for x in launcher.stdout],  # type: ignore[union-attr]
                              daemon=True)
    reader.start()
    seen: list[str] = []
    peer = None
    try:
        deadline = time.monotonic() + 40
        while not any("[ros2] fleet 'turtle'" in line for line in seen):
            assert time.monotonic() < deadline, "".join(seen)
            seen.append(lines.get(timeout=max(0.1, deadline - time.monotonic())))
        peer = subprocess.run([sys.executable, str(Path(__file__).with_name(
            "sdk_own_types_peer.py")), str(port), str(tmp_path / "msgs"), "/pose",
            "turtle_msgs/msg/Pose"], capture_output=True, text=True, timeout=60,
            env=dict(child_env(), ZENOH_CONFIG_OVERRIDE="scouting/multicast/enabled=false"))
        events = {e["event"]: e for e in map(json.loads, peer.stdout.splitlines())
                  if e.get("event")}
        assert dict(events["topics"]["topics"])["/pose"] == ["turtle_msgs/msg/Pose"], peer
        sample = events["sample"]
        assert (sample["y"], sample["theta"], sample["name"]) == (2.0, 0.25, "turtle1"), sample
        assert sample["x"] > 0 and sample["x"] % 0.5 == 0, sample
    finally:
        # `communicate` in `_stop` and the reader thread both read the launcher's output:
        # its last lines (the verdict) reach either one
        rest = _stop(launcher)
        router.close()
        reader.join(10)
        while not lines.empty():
            seen.append(lines.get())
        out = "".join(seen) + rest
    assert "names no ROS 2 mapping" not in out and "INCONCLUSIVE" not in out, out[-3000:]
    assert "result: interrupted (SIGINT received)" in out, out[-3000:]


def test_a_bridge_that_never_reaches_its_router_makes_the_run_inconclusive(tmp_path):
    scenario = _fleet(tmp_path / "turtle")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    dead = f"tcp/127.0.0.1:{pick_free_port()}"  # nothing listens there
    # the mapping lives beside the scenario: found from another working directory
    proc = _launch(scenario, elsewhere, "--ros2", "--ros2-router", dead, "--ros2-mapping",
                   "turtle_map:Mapping", "--timeout", "2")
    out = _stop_after(proc, 60)
    assert proc.returncode == 3, out[-3000:]
    assert (f"result: INCONCLUSIVE (the ROS 2 bridge never reached its router at {dead}"
            in out), out[-3000:]


def test_a_mapping_that_does_not_load_is_one_line_before_anything_starts(tmp_path):
    scenario = _fleet(tmp_path / "turtle")
    proc = _launch(scenario, tmp_path, "--ros2", "--ros2-mapping", "turtle_map:Mapin")
    out = _stop_after(proc, 60)
    assert proc.returncode == 2, out
    assert len(out.strip().splitlines()) == 1, out
    assert "--ros2-mapping: unknown ROS 2 mapping 'turtle_map:Mapin'" in out, out
    assert out.strip().endswith("; did you mean 'turtle_map:Mapping'?"), out
    assert "[launcher]" not in out


def _stop_after(proc: subprocess.Popen[str], timeout: float) -> str:
    """The launcher's output once it ended (killed after `timeout`), what it started ended."""
    try:
        out, _ = proc.communicate(timeout=timeout)
        return out
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate(timeout=5)
        kill_all(spawned_by(proc.pid))
