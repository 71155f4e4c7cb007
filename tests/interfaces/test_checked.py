"""The checker with standard ROS 2 types in messages and in node state (native nodes)."""

from __future__ import annotations

import pytest

from tests.interfaces.twist_nodes import Keeper, TwoCommands
from twinfleet.runtime.contract.kinds import Status
from twinfleet.testing import check, invariant, system

pytestmark = pytest.mark.timeout(120)


def test_a_twist_kept_in_state_is_checked_and_read_by_properties():
    built = system({"sender": TwoCommands, "keeper": Keeper}, [
        invariant("second_is_last", "keeper.heard < 2 or keeper.last.linear.x == 2.0")])
    report = check(built)
    assert report.verdict is Status.HOLDS, report.message
    assert report.states == 3  # after the start, each Twist taken in turn (FIFO per sender)
    wrong = system({"sender": TwoCommands, "keeper": Keeper}, [
        invariant("never_two", "keeper.last.linear.x < 2.0")])
    assert check(wrong).verdict is Status.VIOLATED
