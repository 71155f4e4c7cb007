"""The rclpy conformance programs: each runs under real rclpy (the oracle), under twinfleet
live and in the checker; where the outcome is deterministic, real rclpy and the live fleet
agree, and the checker's verdict says the same for every interleaving."""

from __future__ import annotations

import time

import pytest

from tests.rclpy.oracle import (
    PROGRAMS,
    launch,
    real_rclpy,
    real_rclpy_background,
    running_fleet,
    twinfleet,
    wait_for_line,
)
from twinfleet import testing

pytestmark = pytest.mark.timeout(300)

HEARD = ["hello 1", "hello 2", "hello 3"]


def check(scenario: str) -> testing.CheckReport:
    return testing.check(PROGRAMS / scenario)


def test_chatter_checks():
    report = check("chatter.yaml")
    assert report.holds, report.explain()


def test_done_callback_checks():
    report = check("toggle_done.yaml")
    assert report.holds, report.explain()


def test_await_in_reentrant_group_checks():
    report = check("toggle_await.yaml")
    assert report.holds, report.explain()


@pytest.mark.parametrize("scenario", ["tuning.yaml", "blinking.yaml", "chatter_lab.yaml"])
def test_parameters_timers_and_remapping_check(scenario):
    report = check(scenario)
    assert report.holds, report.explain()


def test_await_in_default_group_hangs_in_the_checker():
    report = check("toggle_hang.yaml")
    assert report.violated and report.property == "answered", report.explain()
    assert "never holds on a reachable cycle" in report.message
    assert report.trace is not None
    last = [s["changed"]["awaiting"] for s in report.trace["steps"] if "awaiting" in s["changed"]]
    task = last[-1]["tasks"][0]  # the suspended callback, holding the default group (0)
    assert task["callback"] == "tick" and task["group"] == 0
    assert [w[0] for w in last[-1]["waiting"]] == ["client", "timer"]  # held back by it
    assert dict(last[-1]["attrs"])["calls"] == 1


@pytest.mark.slow
def test_chatter_under_real_rclpy():
    assert real_rclpy("chatter")["listener"]["heard"] == HEARD


@pytest.mark.slow
def test_toggle_under_real_rclpy():
    assert real_rclpy("toggle")["caller"]["replies"] == ["on #1", "off #2", "on #3"]
    assert real_rclpy("toggle", "awaiting")["awaiting"]["replies"] == ["on #1", "on #2", "on #3"]
    hung = real_rclpy("toggle", "awaiting", "--ros-args", "-p", "reentrant:=false")
    assert hung["awaiting"] == {"replies": [], "calls": 1}
    assert hung["switch"] == {"requests": 1}


@pytest.mark.slow
def test_parameters_under_real_rclpy():
    tuned = real_rclpy("tuning", "--ros-args", "-p", "gain:=0.5")["tuner"]
    assert tuned == {"initial": [0.5, "auto"], "final": [2.0, "manual"],
                     "outcomes": [["gain", True], ["gain", False], ["mode", True]]}


@pytest.mark.slow
def test_timers_under_real_rclpy():
    assert real_rclpy("blinking")["blinker"] == {"events": ["a", "a", "b", "a", "a"],
                                                "canceled": [True, True]}


@pytest.mark.slow
def test_node_per_process_under_real_rclpy():
    """As `ros2 run` starts them: one process per node, renamed and parametrised by
    --ros-args; the scenario chatter_lab.yaml says the same with name, namespace, params."""
    with real_rclpy_background("chatter", "listener", "--ros-args", "-r", "__ns:=/lab") as heard:
        talker = real_rclpy("chatter", "talker", "--ros-args", "-r", "__ns:=/lab", "-r",
                            "__node:=speaker", "-p", "limit:=2", domain=heard.domain)
    assert talker == {"speaker": {"sent": 2}}
    assert heard.result() == {"listener": {"heard": ["hello 1", "hello 2"]}}


@pytest.mark.slow
@pytest.mark.fleet
@pytest.mark.parametrize("scenario", ["chatter.yaml", "toggle_done.yaml", "toggle_await.yaml",
                                      "tuning.yaml", "blinking.yaml", "chatter_lab.yaml"])
def test_live_fleet_agrees(scenario):
    run = launch(scenario)
    assert "result: PASSED" in run.stdout, run.stdout + run.stderr


@pytest.mark.slow
@pytest.mark.fleet
def test_live_fleet_hangs_in_the_default_group():
    run = launch("toggle_hang.yaml", timeout_s=3.0)
    assert run.returncode == 1 and "result: FAILED" in run.stdout, run.stdout + run.stderr
    assert "awaiting" in run.stdout


@pytest.mark.slow
def test_transient_local_late_joiner_under_real_rclpy():
    with real_rclpy_background("latched") as mapper:
        time.sleep(1.5)  # the late joiner: started once the mapper has published both
        reader = real_rclpy("latched", "reader", domain=mapper.domain)
    assert reader == {"reader": {"maps": ["map v2"]}}
    assert mapper.result() == {"mapper": {"versions": 2}}


@pytest.mark.slow
@pytest.mark.fleet
def test_transient_local_late_joiner_live():
    with running_fleet("latched.yaml") as fleet:
        wait_for_line(fleet, "published held")  # the late joiner: after both versions
        echo = twinfleet("topic", "echo", "/map", "--once", "--fleet", "latched", timeout_s=30.0)
    assert echo.stdout.startswith("data: map v2"), echo
