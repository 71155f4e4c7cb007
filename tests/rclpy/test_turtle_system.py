"""The 97-line rclpy turtle system (programs/turtle_system.py) runs as written under every
command: check, replay of its counterexample (and on the live fleet), --statistical,
sweep, launch, and validate of a live run against the checker's model."""

from __future__ import annotations

import json

import pytest

from tests.rclpy.oracle import launch, running_fleet, twinfleet, wait_for_line

pytestmark = pytest.mark.timeout(300)


def test_check_holds():
    run = twinfleet("check", "turtle_system.yaml")
    assert run.returncode == 0 and "verdict: HOLDS" in run.stdout, run.stdout + run.stderr
    assert "states 49 " in run.stdout  # unreduced: far fewer worlds than por waits for


def test_a_violation_replays(tmp_path):
    trace = tmp_path / "fence.trace.json"
    run = twinfleet("check", "turtle_system.yaml", "controller.goal:=5", "--trace-out", str(trace))
    assert run.returncode == 1 and "VIOLATED fence" in run.stdout, run.stdout + run.stderr
    replay = twinfleet("replay", str(trace))
    assert replay.returncode == 1 and "replay confirmed: fence violated" in replay.stdout, (
        replay.stdout + replay.stderr)


def test_statistical():
    run = twinfleet("check", "turtle_system.yaml", "--statistical", "--simulations", "50")
    assert run.returncode == 0, run.stdout + run.stderr
    assert "50 simulations" in run.stdout and "0 / 50" in run.stdout


def test_sweep(tmp_path):
    run = twinfleet("sweep", "turtle_system.yaml", "--param", "controller.goal=4,5",
                    "--param", "controller.step=1,2", "--workers", "1", "--out", str(tmp_path))
    assert run.returncode in (0, 1), run.stdout + run.stderr
    points = json.loads((tmp_path / "sweep.json").read_text())
    verdicts = {(p["params"]["controller.goal"], p["params"]["controller.step"]): p["verdict"]
                for p in points["points"]}
    assert verdicts == {(4, 1): "holds", (4, 2): "holds", (5, 1): "violated",
                        (5, 2): "violated"}, points


@pytest.mark.slow
@pytest.mark.fleet
def test_launch():
    run = launch("turtle_system.yaml")
    assert run.returncode == 0 and "result: PASSED" in run.stdout, run.stdout + run.stderr


@pytest.mark.slow
@pytest.mark.fleet
def test_interface_show_and_topic_pub_reach_an_rclpy_fleet():
    shown = twinfleet("interface", "show", "geometry_msgs/msg/Twist")
    assert "geometry_msgs/Vector3 linear" in shown.stdout, shown.stdout + shown.stderr
    with running_fleet("turtle_system.yaml", timeout_s=8.0) as fleet:
        wait_for_line(fleet, "two_laps held")  # two laps done: the controller stops commanding
        pub = twinfleet("topic", "pub", "/cmd_vel", "geometry_msgs/msg/Twist",
                        "{linear: {x: 5.0}}", "--once", "--fleet", "turtle_system",
                        timeout_s=30.0)
        assert pub.returncode == 0, pub.stdout + pub.stderr
        out, _ = fleet.communicate(timeout=60)
    # the turtle moved 5 on the outside command; the monitor saw it past the goal
    assert "within_goal violated" in out and "monitor: rclpy node(farthest=5)" in out, out


@pytest.mark.slow
@pytest.mark.fleet
def test_validate_explains_a_live_run(tmp_path):
    events = tmp_path / "turtle.events.jsonl"
    run = launch("turtle_system.yaml", "--record-events", str(events))
    assert run.returncode == 0, run.stdout + run.stderr
    valid = twinfleet("validate", str(events), "turtle_system.yaml")
    assert valid.returncode == 0 and valid.stdout.startswith("VALID"), valid.stdout + valid.stderr


@pytest.mark.slow
@pytest.mark.fleet
def test_a_violation_replays_on_the_live_fleet(tmp_path):
    trace = tmp_path / "fence.trace.json"
    twinfleet("check", "turtle_system.yaml", "controller.goal:=5", "--trace-out", str(trace))
    live = twinfleet("replay", str(trace), "--live", timeout_s=180.0)
    assert "live replay CONFIRMED: fence" in live.stdout, live.stdout + live.stderr
    assert "final node states: equal to the checker's final world" in live.stdout
