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


GATE_ORDERS = (["run", "other", "poke"], ["run", "poke", "other"])


def gate(*properties: testing.PropertyConfig) -> testing.CheckReport:
    return testing.check(testing.system({"pinger": "interleave:Pinger", "gate": "interleave:Gate"},
                                        list(properties)))


@pytest.mark.parametrize("order", GATE_ORDERS)
def test_callbacks_held_by_a_busy_group_run_in_every_order(order):
    """While `run` awaits in the default group, the second timer and the poke wait; when it
    ends, the checker explores both orders (rclpy's order in one wait set is no promise)."""
    report = gate(testing.invariant("not_this_order", f"gate.order != {order}"))
    assert report.violated, report.explain()


@pytest.mark.slow
def test_real_rclpy_takes_one_of_the_explored_orders():
    assert real_rclpy("interleave", "gate")["gate"]["order"] in GATE_ORDERS


class Pick:
    """Answers ctx.choose with one index."""

    def __init__(self, index: int) -> None:
        self.index = index

    def choose(self, n: int) -> int:
        return self.index


@pytest.mark.parametrize(("index", "order"), [(0, GATE_ORDERS[0]), (1, GATE_ORDERS[1])])
def test_a_freed_group_lets_the_chooser_order_its_waiting_callbacks(index, order):
    from twinfleet.interfaces import freeze, load_interface
    from twinfleet.runtime.contract.context import Context

    node = testing.system({"pinger": "interleave:Pinger", "gate": "interleave:Gate"}).node(
        "gate").instantiate()
    node.start(Context(node, 0))
    node.timer(Context(node, 100), 0)  # run: calls, suspends holding the default group
    node.timer(Context(node, 100), 1)  # other: waits
    node.on_poke(Context(node, 100), freeze(load_interface("std_msgs", "msg").String(data="p")))
    assert [w.kind.value for w in node._tf_engine.dyn.waiting] == ["timer", "subscription"]
    reply = freeze(load_interface("std_srvs", "srv").Trigger.Response(success=True))
    ctx = Context(node, 100, Pick(index))
    node.reply_0(ctx, reply)  # run ends; the group frees; the chooser picks who goes first
    assert ctx.choices == [index] and node.rclpy_node.order == order
