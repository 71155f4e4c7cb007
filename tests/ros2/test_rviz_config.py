"""The shipped RViz2 config: package data, fixed frame map, every topic it shows is one the
bridge publishes for the robot fleet (with the QoS the bridge offers), and its goal tool
publishes the topic the README routes to a robot."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest
import yaml

from tests.support import ROOT
from twinfleet.nodes.msgs import ObstacleScan, OccupancyGrid, RobotPose
from twinfleet.nodes.msgs import Path as PlanMsg
from twinfleet.nodes.ros2_mapping import RobotRos2Mapping
from twinfleet.ros2.commands import rviz_config
from twinfleet.runtime.contract.messages import to_plain

pytestmark = pytest.mark.offline  # starts no fleet, opens no Zenoh session


def _published_by_the_bridge() -> set[str]:
    mapping = RobotRos2Mapping()
    grid = OccupancyGrid(4, 4, 0.5, (0.0, 0.0, 0.0), bytes(16))
    made = [*mapping.outbound("/map", "twinfleet_msgs/OccupancyGrid", to_plain(grid), 0)]
    for i in range(1, 6):
        r = f"r{i}"
        made += mapping.outbound("/poses", "twinfleet_msgs/RobotPose",
                                 to_plain(RobotPose(r, (1, 1), 0, 0)), 0)
        made += mapping.outbound(f"/{r}/scan", "twinfleet_msgs/ObstacleScan",
                                 to_plain(ObstacleScan(r, ((2, 2),))), 0)
        made += mapping.outbound(f"/{r}/path", "twinfleet_msgs/Path",
                                 to_plain(PlanMsg(((1, 2),))), 0)
    return {topic for topic, _, _ in made}


def test_the_rviz_config_shows_what_the_bridge_publishes():
    path = rviz_config()
    assert path.is_file() and path.parent.parent == ROOT / "twinfleet" / "ros2"
    data = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert "rviz/*.rviz" in data["package-data"]["twinfleet.ros2"]
    doc = yaml.safe_load(path.read_text())
    manager = doc["Visualization Manager"]
    assert manager["Global Options"]["Fixed Frame"] == "map"
    shown = {d["Topic"]["Value"]: d["Topic"] for d in manager["Displays"] if "Topic" in d}
    published = _published_by_the_bridge()
    assert set(shown) <= published and {"/map", "/r1/scan", "/r5/plan"} <= set(shown)
    assert shown["/map"]["Durability Policy"] == "Transient Local"  # the bridge latches /map
    assert all(t["Durability Policy"] == "Volatile" for n, t in shown.items() if n != "/map")
    tf = [d for d in manager["Displays"] if d["Class"] == "rviz_default_plugins/TF"]
    assert tf and "/tf" in published
    goal = [t for t in manager["Tools"] if t["Class"] == "rviz_default_plugins/SetGoal"]
    assert goal[0]["Topic"]["Value"] == "/goal_pose"
    assert Path(path).read_text().startswith("# RViz2 config")
