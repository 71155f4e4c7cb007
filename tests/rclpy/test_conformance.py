"""The rclpy conformance programs: each runs under real rclpy (the oracle), under twinfleet
live and in the checker; where the outcome is deterministic, real rclpy and the live fleet
agree, and the checker's verdict says the same for every interleaving."""

from __future__ import annotations

import pytest

from tests.rclpy.oracle import PROGRAMS, launch, real_rclpy
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


def test_await_in_default_group_hangs_in_the_checker():
    report = check("toggle_hang.yaml")
    assert report.violated and report.property == "answered", report.explain()
    assert "never holds on a reachable cycle" in report.message
    assert report.trace is not None
    last = [s["changed"]["awaiting"] for s in report.trace["steps"] if "awaiting" in s["changed"]]
    task = last[-1]["tasks"][0]  # the suspended callback, holding the default group (0)
    assert task["callback"] == {"name": "tick"} and task["group"] == 0
    assert [w[0] for w in last[-1]["waiting"]] == ["client", "timer"]  # held back by it
    assert last[-1]["attrs"]["calls"] == 1


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
@pytest.mark.fleet
@pytest.mark.parametrize("scenario", ["chatter.yaml", "toggle_done.yaml", "toggle_await.yaml"])
def test_live_fleet_agrees(scenario):
    run = launch(scenario)
    assert "result: PASSED" in run.stdout, run.stdout + run.stderr


@pytest.mark.slow
@pytest.mark.fleet
def test_live_fleet_hangs_in_the_default_group():
    run = launch("toggle_hang.yaml", timeout_s=3.0)
    assert run.returncode == 1 and "result: FAILED" in run.stdout, run.stdout + run.stderr
    assert "awaiting" in run.stdout
