"""Standard ROS 2 types on the command line of a running fleet: `interface show`, `topic pub`
with ROS 2 users' YAML (nested maps, the rest defaults) and `topic echo`.

The fleet's nodes speak geometry_msgs/Twist (`twinfleet.interfaces`); the commands run
as separate processes that never import the nodes' module.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml
from itest_support import launch_in, poll, run_cli_in, stop_launch

pytestmark = [pytest.mark.slow, pytest.mark.timeout(120)]
NODES = "tests.interfaces.twist_nodes"


@pytest.fixture(scope="module")
def runtime_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("xdg-runtime")


@pytest.fixture(scope="module")
def fleet(runtime_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    folder = tmp_path_factory.mktemp("twist")
    scenario, log = folder / "twist.yaml", folder / "fleet.log"
    scenario.write_text(yaml.safe_dump({"name": "twist", "nodes": [
        {"name": "follower", "class": f"{NODES}:Follower"},
        {"name": "driver", "class": f"{NODES}:Driver"}]}))
    proc = launch_in(runtime_dir, log, str(scenario), "--timeout", "300")
    try:
        assert poll(lambda: log.read_text().count("started") >= 2 or proc.poll() is not None, 40)
        assert proc.poll() is None, log.read_text()
        yield log
    finally:
        stop_launch(proc)


def ok(result) -> str:
    assert result.returncode == 0, result.stdout + result.stderr
    assert "Traceback" not in result.stderr
    return result.stdout


def test_interface_show_prints_the_ros_definition(runtime_dir):
    shown = ok(run_cli_in(runtime_dir, "interface", "show", "geometry_msgs/msg/Twist"))
    lines = shown.splitlines()
    assert lines[0].startswith("# geometry_msgs/msg/Twist (")
    assert lines[1:] == ["geometry_msgs/Vector3 linear", "\tfloat64 x", "\tfloat64 y",
                         "\tfloat64 z", "geometry_msgs/Vector3 angular", "\tfloat64 x",
                         "\tfloat64 y", "\tfloat64 z"]
    service = ok(run_cli_in(runtime_dir, "interface", "show", "std_srvs/srv/SetBool"))
    assert service.splitlines()[1:] == ["bool data", "---", "bool success", "string message"]


def test_topic_pub_takes_ros_yaml_with_defaults(runtime_dir, fleet):
    out = ok(run_cli_in(runtime_dir, "topic", "pub", "/cmd_vel", "geometry_msgs/msg/Twist",
                        "{linear: {x: 1.0}}", "--fleet", "twist"))
    assert "published #1 on /cmd_vel: geometry_msgs/Twist" in out
    assert poll(lambda: "cmd x=1.0 y=0.0" in fleet.read_text(), 10), fleet.read_text()[-2000:]
    bad = run_cli_in(runtime_dir, "topic", "pub", "/cmd_vel", "geometry_msgs/msg/Twist",
                     "{linear: {w: 1.0}}", "--fleet", "twist")
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1
    assert "Twist.linear: unknown field 'w'" in bad.stderr


def test_topic_echo_prints_the_twist(runtime_dir, fleet):
    [heard] = [d for d in yaml.safe_load_all(ok(run_cli_in(
        runtime_dir, "topic", "echo", "/odom_twist", "--once", "--fleet", "twist"))) if d]
    assert heard["linear"]["x"] == 0.5 and heard["angular"]["z"] == -0.25
