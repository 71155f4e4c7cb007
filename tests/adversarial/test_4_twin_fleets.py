"""Failure 4: two fleets of one name merged silently.

Before: a second `twinfleet launch` of the same scenario with `--connect` to
the running fleet's router started a second r1...r5 on the same keys; both
runs ended with 16 collisions. Now the second launch looks at the router's
liveliness tokens first and refuses with exit 2, naming the nodes; the first
run is untouched.
"""

from __future__ import annotations

import subprocess
import sys

import pytest

from tests.adversarial.harness import running_fleet
from tests.support import ROOT, child_env

pytestmark = [pytest.mark.slow, pytest.mark.timeout(90)]


def test_a_second_launch_of_a_running_fleet_is_refused(tmp_path) -> None:
    with running_fleet(tmp_path, "twins", goal=25, scale=2.0) as fleet:
        second = subprocess.run([sys.executable, "-m", "twinfleet", "launch", str(fleet.scenario),
                                 "--connect", fleet.endpoint], capture_output=True, text=True,
                                timeout=30, env=child_env(), cwd=ROOT, check=False)
        assert second.returncode == 2, second.stdout + second.stderr
        lines = second.stderr.strip().splitlines()
        assert len(lines) == 1, second.stderr
        assert "fleet 'twins'" in lines[0] and "map_server, r1, r2" in lines[0], lines[0]
        assert "[r1]" not in second.stdout  # no node process was started
        code = fleet.wait_end(60)
        out = fleet.output()
    assert "started (3 nodes alive)" in out and "nodes alive)" not in out.replace(
        "started (3 nodes alive)", "")
    assert "collisions: none" in out and "result: PASSED" in out and code == 0, out[-2000:]
