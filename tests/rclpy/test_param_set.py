"""`twinfleet param set` reaches a running rclpy node: through its on-set callbacks, which
may refuse the value (tests/rclpy/programs/tuning.py refuses a negative gain)."""

from __future__ import annotations

import subprocess
import sys
import time

import pytest

from tests.rclpy.oracle import PROGRAMS, twinfleet
from tests.support import child_env

pytestmark = [pytest.mark.timeout(120), pytest.mark.slow, pytest.mark.fleet]


def _set(*args: str) -> subprocess.CompletedProcess[str]:
    return twinfleet("param", "set", "--fleet", "tuning", *args, timeout_s=30.0)


def test_param_set_reaches_the_on_set_callback():
    fleet = subprocess.Popen([sys.executable, "-m", "twinfleet", "launch", "tuning.yaml",
                              "--timeout", "30"], cwd=PROGRAMS, env=child_env(),
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 60
        refused = _set("tuner", "gain", "--", "-2.0")
        while "successful" not in refused.stdout and time.monotonic() < deadline:
            time.sleep(0.5)  # the fleet is still starting: no server yet
            refused = _set("tuner", "gain", "--", "-2.0")
        assert "successful: false" in refused.stdout, refused.stdout + refused.stderr
        assert "gain must be >= 0" in refused.stdout
        accepted = _set("tuner", "gain", "3.0")
        assert "successful: true" in accepted.stdout, accepted.stdout + accepted.stderr
        unknown = _set("tuner", "nope", "1")
        assert "is not declared" in unknown.stdout, unknown.stdout + unknown.stderr
    finally:
        fleet.terminate()
        try:
            fleet.wait(timeout=30)
        except subprocess.TimeoutExpired:
            fleet.kill()
            fleet.wait()
