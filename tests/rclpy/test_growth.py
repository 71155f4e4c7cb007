"""The state-growth diagnosis reads an rclpy node's attributes one by one: a counter kept
as ``self.count`` is named (``counter.attrs.count``), not hidden in the node's one
``attrs`` field."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.checker.helpers import run, scenario
from tests.rclpy.oracle import in_process_env
from twinfleet.runtime.contract.kinds import Status

pytestmark = pytest.mark.timeout(120)

in_process_env()

COUNTER = '''
from rclpy.node import Node
from std_msgs.msg import Int32


class Counter(Node):
    def __init__(self):
        super().__init__("counter")
        self.count = 0
        self.phase = 0
        self.pub = self.create_publisher(Int32, "count", 10)
        self.create_timer(0.1, self.tick)

    def tick(self):
        self.count += 1
        self.phase = (self.phase + 1) % 4
        self.pub.publish(Int32(data=self.count))
'''


def test_an_rclpy_counter_never_reset_is_named(tmp_path: Path) -> None:
    (tmp_path / "growing_counter.py").write_text(COUNTER)
    path = scenario(tmp_path, [{"name": "counter", "class": "growing_counter:Counter"}],
                    properties=[{"kind": "invariant", "name": "ok", "expr": "counter.count >= 0"}],
                    name="growing")
    result = run(path, max_states=3000)
    assert result.status is Status.UNKNOWN
    assert [n.name for n in result.growth_notes()] == ["counter.attrs.count"]
    assert "state growth: counter.attrs.count took" in result.summary()
