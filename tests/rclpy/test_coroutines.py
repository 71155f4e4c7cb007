"""Suspended coroutine callbacks, resumed by re-execution (twinfleet/rclpy/tasks.py), against
real rclpy: a callback's local variables survive its awaits, what other callbacks change
meanwhile survives its resumption, and a lost update that real rclpy shows is found by
the checker and confirmed by replay."""

from __future__ import annotations

import pytest

from tests.rclpy.oracle import in_process_env, real_rclpy, twinfleet
from twinfleet import testing

pytestmark = pytest.mark.timeout(300)

in_process_env()

REAL_ORDER = ["start", "poke", "pong 1", "pong 1 then pong 2"]
# The poke and the reply come from one sender, which twinfleet's `ros` semantics keep in
# send order (as one Zenoh session does): the reply never overtakes the poke.
OTHER_ORDER = ["start", "pong 1", "poke", "pong 1 then pong 2"]


def stepper(*properties: testing.PropertyConfig) -> testing.CheckReport:
    system = testing.system({"pinger": "interleave:Pinger", "stepper": "interleave:Stepper"},
                            list(properties))
    return testing.check(system)


def test_locals_and_other_callbacks_survive_the_awaits():
    report = stepper(testing.eventually("done", f"stepper.log == {REAL_ORDER}"))
    assert report.holds, report.explain()


def test_the_reply_never_overtakes_the_poke():
    report = stepper(testing.invariant("order", f"stepper.log[:3] != {OTHER_ORDER[:3]}"))
    assert report.holds, report.explain()


def tally() -> testing.Scenario:
    return testing.system({"pinger": "interleave:Pinger", "tally": "interleave:Tally"},
                          [testing.invariant("no_lost_update",
                                             "tally.finished < 2 or tally.total == 2")])


def test_lost_update_is_found_and_replayed(tmp_path):
    report = testing.check(tally())
    assert report.violated and report.property == "no_lost_update", report.explain()
    trace = report.save_trace(tmp_path / "tally.trace.json")
    replay = twinfleet("replay", str(trace))
    assert replay.returncode == 1 and "replay confirmed" in replay.stdout, (
        replay.stdout + replay.stderr)


@pytest.mark.slow
def test_real_rclpy_agrees():
    assert real_rclpy("interleave")["stepper"]["log"] == REAL_ORDER
    assert real_rclpy("interleave", "tally")["tally"] == {"total": 1, "finished": 2}
