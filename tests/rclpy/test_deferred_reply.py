"""rclpy service callbacks that reply later (tests/rclpy/programs/relay.py): an `async def`
service callback that awaits another service, and a request that waits for its busy
callback group. The checker explores them, a live fleet runs them over Zenoh, a trace
through a deferred reply replays live, and real rclpy (the oracle) agrees."""

from __future__ import annotations

import pytest
import yaml

from tests.rclpy.oracle import PROGRAMS, in_process_env, launch, real_rclpy, twinfleet
from twinfleet import testing

pytestmark = pytest.mark.timeout(300)

in_process_env()


def check(scenario: str, *properties: testing.PropertyConfig) -> testing.CheckReport:
    """Check a relay scenario, or its nodes with `properties` instead of its own."""
    if not properties:
        return testing.check(PROGRAMS / scenario)
    nodes = yaml.safe_load((PROGRAMS / scenario).read_text())["nodes"]
    return testing.check(testing.system({n["name"]: n["class"] for n in nodes}, properties))


@pytest.mark.parametrize("scenario", ["relay.yaml", "relay_two.yaml", "relay_twice.yaml",
                                      "relay_busy.yaml"])
def test_a_deferred_reply_checks(scenario):
    report = check(scenario)
    assert report.holds, report.explain()


@pytest.mark.parametrize(("scenario", "first"), [
    ("relay_two.yaml", "asker.got != '' and other_asker.got == ''"),
    ("relay_two.yaml", "other_asker.got != '' and asker.got == ''"),
    ("relay_twice.yaml", "twice_asker.order == [False]"),
    ("relay_twice.yaml", "twice_asker.order == [True]"),
])
def test_replies_come_back_in_either_order(scenario, first):
    """Each order of the two deferred replies is reachable (and relay_two/relay_twice
    hold in all of them: each caller, each call, gets its own answer)."""
    report = check(scenario, testing.invariant("not_first", f"not ({first})"))
    assert report.violated and report.property == "not_first", report.explain()


@pytest.mark.parametrize("heard", ["''", "'from backend'"])
def test_a_request_waits_for_its_busy_group(heard):
    """Served at once when it comes before the timer's coroutine takes the group; else it
    waits for the group, and is answered after the coroutine heard the backend."""
    got = f'"busy relay heard {heard}"'
    report = check("relay_busy.yaml", testing.invariant("other", f"asker.got != {got}"))
    assert report.violated and report.property == "other", report.explain()


def test_a_relay_that_answers_the_wrong_caller_is_violated(tmp_path):
    report = check("relay_sloppy.yaml")
    assert report.violated and report.property in ("asker_answered", "other_answered"), \
        report.explain()
    assert report.trace is not None
    trace = report.save_trace(tmp_path / "sloppy.trace.json")
    replay = twinfleet("replay", str(trace))
    assert replay.returncode == 1 and "replay confirmed" in replay.stdout, \
        replay.stdout + replay.stderr


@pytest.mark.slow
@pytest.mark.fleet
@pytest.mark.parametrize("scenario", ["relay.yaml", "relay_two.yaml", "relay_twice.yaml",
                                      "relay_busy.yaml"])
def test_a_deferred_reply_runs_live(scenario):
    run = launch(scenario)
    assert "result: PASSED" in run.stdout, run.stdout + run.stderr


@pytest.mark.slow
@pytest.mark.fleet
def test_a_live_run_through_deferred_replies_is_a_path_of_the_model(tmp_path):
    events = tmp_path / "relay_two.events.jsonl"
    run = launch("relay_two.yaml", "--record-events", str(events))
    assert run.returncode == 0, run.stdout + run.stderr
    valid = twinfleet("validate", str(events), "relay_two.yaml")
    assert valid.returncode == 0 and valid.stdout.startswith("VALID"), valid.stdout + valid.stderr


@pytest.mark.slow
@pytest.mark.fleet
def test_a_trace_through_deferred_replies_replays_live(tmp_path):
    trace = check("relay_sloppy.yaml").save_trace(tmp_path / "sloppy.trace.json")
    replay = twinfleet("replay", str(trace), "--live", timeout_s=240.0)
    out = replay.stdout + replay.stderr
    assert "final node states: equal to the checker's final world" in out, out
    assert "live replay CONFIRMED" in out, out


@pytest.mark.slow
def test_real_rclpy_agrees():
    assert real_rclpy("relay")["asker"] == {"got": "from backend"}
    two = real_rclpy("relay", "echo")
    assert two["asker"] == {"got": "from backend (yes)"}
    assert two["other_asker"] == {"got": "from backend (no)"}
    twice = real_rclpy("relay", "twice")["twice_asker"]
    assert sorted(twice["order"]) == [False, True] and twice["mismatched"] == 0, twice
    busy = real_rclpy("relay", "busy")["asker"]["got"]
    assert busy in ("busy relay heard ''", "busy relay heard 'from backend'"), busy
