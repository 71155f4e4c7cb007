"""An rclpy node's state as the checker keeps it (twinfleet/rclpy/state.py, refs.py):
futures, lambdas and partials as done callbacks, a timer made in a callback, tuples,
dicts and messages round-trip through the snapshot bytes and behave alike after."""

from __future__ import annotations

import pytest

from tests.rclpy.oracle import in_process_env
from twinfleet import testing
from twinfleet.runtime.contract.snapshot import restore, snapshot

pytestmark = pytest.mark.timeout(120)

in_process_env()

DONE = ("asker.answers == {'round 1': 'pong 1', 'round 2': 'pong 2'} and "
        "asker.pair == (2, 'pong 2') and asker.last.data == 'round 2 and a follow-up'")


def system() -> testing.Scenario:
    return testing.system({"ponger": "keeper:Ponger", "asker": "keeper:Asker"},
                          [testing.eventually("kept", DONE)])


def test_callbacks_futures_and_timers_in_state_check():
    report = testing.check(system())  # the contract's checks run every new handler twice
    assert report.holds, report.explain()


def test_state_round_trips_through_snapshot_bytes():
    node = system().node("asker").instantiate()
    engine = node._tf_engine
    node.state = node.state  # as the checker sets a state back
    future = engine.node.client.call_async(engine.node.client.srv_type.Request())
    engine.node.pending = future
    future.add_done_callback(lambda f: None)
    engine.node.pair = (1, {"a": [1, 2]})
    data = snapshot(node.state)
    node.state = restore(data)
    assert snapshot(node.state) == data
    rclpy_node = engine.node
    assert rclpy_node.pair == (1, {"a": [1, 2]}) and type(rclpy_node.pair) is tuple
    assert rclpy_node.pending is engine.dyn.calls[0][0]  # one future, found from both
    assert rclpy_node.last.data == "none" and type(rclpy_node.last).__name__ == "String"
    assert len(rclpy_node.pending._callbacks) == 1


def test_clock_time_duration_and_logger():
    system = testing.system({"c": "clocked:Clocked"}, [testing.invariant(
        "not_yet", "not (len(c.stamps) == 2 and c.qos_depth == 5 and "
                   "c.stamps[1] == [0, 500000000, 1000000000])")])
    report = testing.check(system)  # the second tick (t=500 ms) reaches it: a violation
    assert report.violated, report.explain()
    assert report.trace is not None
    logs = [log for step in report.trace["steps"] for log in step["logs"]]
    assert len(logs) == 2 and all("WARN" in str(log) and "tick at" in str(log) for log in logs)
    assert not any("not shown" in str(log) for log in logs)  # DEBUG is below INFO


def test_a_state_reads_as_its_attributes_first():
    """A live violation's report shows each node's state cut to a few hundred characters:
    the node's own attributes come first, as the node has them."""
    node = system().node("asker").instantiate()
    node._tf_engine.node.pair = (1, {"a": [1, 2]})
    shown = repr(node.state)
    assert shown.startswith("rclpy node(") and "pair=(1, {'a': [1, 2]})" in shown
    assert shown.index("pair=") < shown.index("timers=")
