"""What twinfleet's rclpy refuses, and how: blocking idioms inside a callback are the
contract breach (exit 4) naming the idiom to use instead; parts of ROS 2 not offered yet
fail at load with one line naming them."""

from __future__ import annotations

import pytest

from tests.rclpy.oracle import in_process_env, twinfleet
from twinfleet import testing

pytestmark = pytest.mark.timeout(120)

in_process_env()


@pytest.mark.parametrize(("node", "says", "fix"), [
    ("BlockingCall", "Client.call(/ping) blocks inside a callback", "call_async"),
    ("Sleeper", "time.sleep() blocks the executor", "create_timer"),
    ("RateSleeper", "Rate.sleep() blocks inside a callback", "create_timer"),
    ("NestedSpinner", "rclpy.spin_until_future_complete() inside a callback", "call_async"),
])
def test_blocking_idiom_is_a_breach(node, says, fix):
    system = testing.system({"n": f"blocking:{node}", "pinger": "blocking:Pinger"})
    report = testing.check(system)
    assert report.breach, report.explain()
    assert says in report.message and fix in report.message, report.message


def test_blocking_idiom_exits_4_with_one_line(tmp_path):
    scenario = tmp_path / "sleeper.yaml"
    scenario.write_text("name: sleeper\nnodes:\n  - {name: s, class: 'blocking:Sleeper'}\n")
    run = twinfleet("check", str(scenario))
    assert run.returncode == 4, run.stdout + run.stderr
    assert "time.sleep() blocks the executor" in run.stdout + run.stderr


@pytest.mark.parametrize("module", ["rclpy.action", "rclpy.lifecycle", "tf2_ros"])
def test_unsupported_parts_are_named_in_one_line(tmp_path, module):
    (tmp_path / "uses_it.py").write_text(f"import {module}\nfrom rclpy.node import Node\n\n"
                                         "class N(Node):\n    pass\n")
    scenario = tmp_path / "s.yaml"
    scenario.write_text("name: s\nnodes:\n  - {name: n, class: 'uses_it:N'}\n")
    run = twinfleet("check", str(scenario))
    assert run.returncode == 2, run.stdout + run.stderr
    lines = [ln for ln in (run.stdout + run.stderr).splitlines() if ln.strip()]
    assert len(lines) == 1 and "not supported by twinfleet's rclpy yet" in lines[0], lines
    assert module.split(".")[-1] in lines[0]
    assert "nodes[0].class: cannot load node class 'uses_it:N': importing 'uses_it' failed" \
        in lines[0], lines  # the class exists: it is not called unknown


def test_params_are_the_declared_parameters(tmp_path):
    scenario = tmp_path / "s.yaml"
    scenario.write_text("name: s\nnodes:\n  - {name: t, class: 'chatter:Talker', "
                        "params: {limt: 2}}\n")
    run = twinfleet("check", str(scenario))
    assert run.returncode == 2, run.stdout + run.stderr
    assert "nodes[0].params.limt: unknown parameter" in run.stderr and "limit" in run.stderr


def test_only_the_node_codes_thread_may_not_sleep():
    import threading
    import time

    from twinfleet.runtime.contract.context import Context, ContractError

    node = testing.system({"s": "blocking:Sleeper"}).node("s").instantiate()
    errors: list[BaseException] = []

    def other() -> None:
        try:
            time.sleep(0)
        except BaseException as exc:  # noqa: BLE001  (what the other thread met, for the test)
            errors.append(exc)

    with node._tf_engine.handling(Context(node, 0)):
        thread = threading.Thread(target=other)
        thread.start()
        thread.join()
        with pytest.raises(ContractError, match="time.sleep"):
            time.sleep(0)
    assert errors == []
    time.sleep(0)  # put back after the handler
