"""`twinfleet param set` reaches a running rclpy node: through its on-set callbacks, which
may refuse the value (tests/rclpy/programs/tuning.py refuses a negative gain)."""

from __future__ import annotations

import subprocess

import pytest

from tests.rclpy.oracle import running_fleet, twinfleet, wait_for_line

pytestmark = [pytest.mark.timeout(120), pytest.mark.slow, pytest.mark.fleet]


def _set(*args: str) -> subprocess.CompletedProcess[str]:
    return twinfleet("param", "set", "--fleet", "tuning", *args, timeout_s=30.0)


def test_param_set_reaches_the_on_set_callback():
    with running_fleet("tuning.yaml") as fleet:
        wait_for_line(fleet, "tuned held")
        refused = _set("tuner", "gain", "--", "-2.0")
        accepted = _set("tuner", "gain", "3.0")
        got = twinfleet("param", "get", "--fleet", "tuning", "tuner", "gain", timeout_s=30.0)
        unknown = _set("tuner", "nope", "1")
    assert "successful: false" in refused.stdout, refused.stdout + refused.stderr
    assert "gain must be >= 0" in refused.stdout
    assert "successful: true" in accepted.stdout, accepted.stdout + accepted.stderr
    assert got.stdout.strip() == "Double value is: 3.0", got.stdout + got.stderr
    assert "is not declared" in unknown.stdout, unknown.stdout + unknown.stderr
