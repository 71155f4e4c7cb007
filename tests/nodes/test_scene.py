"""The robot scene: what the viewers draw of the robot fleet's messages and checker states."""

from __future__ import annotations

import math

import msgpack
import pytest

from twinfleet.nodes.msgs import (
    Collision,
    FleetStatus,
    ObstacleScan,
    OccupancyGrid,
    Path,
    RobotPose,
    RobotStatus,
)
from twinfleet.nodes.scene import HALF_M, RobotScene, heading
from twinfleet.runtime.contract import scene as draw
from twinfleet.runtime.contract.messages import encode
from twinfleet.runtime.scenario.scenes import load_scene


def drawn(topic: str, msg: object) -> list[draw.Drawing]:
    """What the scene draws of `msg` as a viewer decodes it off the wire."""
    env = msgpack.unpackb(encode(msg), raw=False)
    return RobotScene().drawings(topic, env["type"], env["data"])


def test_the_robot_scene_is_a_scene_loaded_by_its_import_name():
    scene = load_scene("twinfleet.nodes.scene:RobotScene")
    assert isinstance(scene, draw.Scene) and isinstance(scene, RobotScene)
    assert scene.columns == ("mode", "cell", "goal", "waits", "failures", "arrived")


def test_directions_turn_counter_clockwise_from_plus_row():
    assert heading(2) == 0.0  # +column: +x
    assert heading(0) == pytest.approx(math.pi / 2)  # +row: +y
    assert heading(4) == pytest.approx(-math.pi / 2)
    assert heading(9) == heading(1)


def test_grid_pose_status_scan_path_collision_and_order():
    grid = OccupancyGrid(3, 2, 0.25, (1.0, 2.0, 0.0), bytes([0, 100, 0, 0, 0, 100]))
    assert drawn("/map", grid) == [draw.Grid(3, 2, 0.25, (1.0, 2.0), grid.data)]
    assert drawn("/poses", RobotPose("r1", (2, 3), 2, 1, True)) == [
        draw.Body("r1", 3.5, 2.5, 0.0, HALF_M),
        draw.Row("r1", (("cell", "(2,3)"), ("arrived", "yes")))]
    assert drawn("/r1/status", RobotStatus("r1", "waiting", (2, 3), (4, 5), 2, 1, 70)) == [
        draw.Row("r1", (("mode", "waiting"), ("cell", "(2,3)"), ("goal", "(4,5)"), ("waits", "2"),
                        ("failures", "1"), ("arrived", "no"))),
        draw.Body("r1", 3.5, 2.5, None, HALF_M),  # a status does not say the heading
        draw.Goal("r1", (5.5, 4.5))]
    assert drawn("/r1/scan", ObstacleScan("r1", ((0, 0), (1, 2)))) == [
        draw.Scan("r1", ((0.5, 0.5), (2.5, 1.5)))]
    assert drawn("/r1/path", Path(((2, 4), (2, 5)))) == [draw.Plan("r1", ((4.5, 2.5), (5.5, 2.5)))]
    assert drawn("/generate_path", Path(((2, 4),))) == []  # a service reply is nobody's plan
    assert drawn("/collisions", Collision("r1", "r2", (0, 1), (1, 1), 60)) == [
        draw.Collision(((1.5, 0.5), (1.5, 1.5)), "t=60 ms r1(0,1) × r2(1,1)", "r1 × r2 at t=60 ms")]
    assert drawn("/fleet_status", FleetStatus(("r2", "r1"), ((0, 0), (1, 1)), 0, 5)) == [
        draw.Order(("r2", "r1"))]


def test_unexpected_shapes_and_other_types_draw_nothing():
    scene = RobotScene()
    assert scene.drawings("/poses", "twinfleet_msgs/RobotPose", {"robot": "r1", "cell": [1]}) == []
    assert scene.drawings("/poses", "twinfleet_msgs/RobotPose", {"cell": [1, 1]}) == []
    assert scene.drawings("/map", "twinfleet_msgs/OccupancyGrid", {"data": "AAA="}) == []
    assert scene.drawings("/chatter", "std_msgs/String", {"data": "hi"}) == []
    pose = scene.drawings("/poses", "twinfleet_msgs/RobotPose", {"robot": "r1", "cell": [1, 1]})
    assert pose[0] == draw.Body("r1", 1.5, 1.5, None, HALF_M)  # no direction: heading unsaid


def test_checker_states_draw_robots_with_their_plan_scan_start_goal_and_last_collision():
    states = {
        "map_server": {"collisions": 1, "collided": [["r1", "r2"]]},
        "r1": {"cell": [5, 4], "dir": 2, "moves": [[5, 3], [5, 4], [5, 5]], "move_idx": 2,
               "obstacles": [[5, 6]], "waits": 3, "failures": 1, "waiting": True},
        "r2": {"cell": [5, 5], "dir": 6, "done": True},
    }
    params = {"r1": {"start": [5, 1], "goal": [5, 10]}, "r2": {"start": [5, 10], "goal": [5, 1]}}
    out = RobotScene().state_drawings(states, params)
    assert out[0] == draw.Order(("r1", "r2"))
    r1 = [d for d in out if getattr(d, "name", None) == "r1"]
    assert r1 == [
        draw.Body("r1", 4.5, 5.5, 0.0, HALF_M),
        draw.Row("r1", (("mode", "waiting"), ("cell", "(5,4)"), ("goal", "(5,10)"),
                        ("waits", "3"), ("failures", "1"), ("arrived", "no"))),
        draw.Scan("r1", ((6.5, 5.5),)),
        draw.Plan("r1", ((5.5, 5.5),)),  # the moves from move_idx on
        draw.Start("r1", (1.5, 5.5)),
        draw.Goal("r1", (10.5, 5.5))]
    r2_row = next(d for d in out if isinstance(d, draw.Row) and d.name == "r2")
    assert dict(r2_row.values)["mode"] == "arrived" and dict(r2_row.values)["waits"] == "–"
    assert out[-1] == draw.Collision(((4.5, 5.5), (5.5, 5.5)), "(5,4) × (5,5)", "(5,4) × (5,5)")
    states["map_server"]["collisions"] = 0
    assert not any(isinstance(d, draw.Collision) for d in RobotScene().state_drawings(states, params))
