"""A stop is the launcher's, not a node's: the timeout counts from the fleet's epoch (every
node alive), a run stopped before the fleet is up is INCONCLUSIVE saying so, and a node the
launcher stops while it still imports leaves quietly (no traceback, never "failed")."""

from __future__ import annotations

import asyncio
import io

import pytest

from tests.adversarial.fleets import run_launch, write_scenario
from twinfleet.runtime.fleet.launcher import LaunchOptions, run_fleet
from twinfleet.runtime.fleet.live_verdict import Status
from twinfleet.runtime.scenario.spec import load_scenario

pytestmark = [pytest.mark.slow, pytest.mark.timeout(90)]

SLOW_MODULE = '''
import sys
import time
from twinfleet import Node

if "--node" in sys.argv and sys.argv[sys.argv.index("--node") + 1] == "b":
    time.sleep({seconds})  # node b's heavy import on a loaded machine


class Slow(Node):
    """Nothing but a slow start."""
'''


def _scenario(tmp_path, seconds: float):
    (tmp_path / "slowstart.py").write_text(SLOW_MODULE.format(seconds=seconds))
    return write_scenario(tmp_path, "slowstart",
                          [{"name": "a", "class": "Counter"},
                           {"name": "b", "class": "slowstart:Slow"}],
                          [{"name": "counts", "kind": "invariant", "expr": "a.count >= 0"}])


def test_a_timeout_shorter_than_the_start_up_counts_from_the_epoch(tmp_path):
    run = run_launch(_scenario(tmp_path, 2.0), "--timeout", "0.5")
    out = run.stdout
    assert "Traceback" not in out and "KeyboardInterrupt" not in out, out
    assert "failed" not in out and "FAILED" not in out, out
    assert "run ended: timeout after 0.5 s" in out, out
    assert "result: PASSED" in out, out
    assert run.returncode == 0, out


def test_a_fleet_not_up_in_time_is_inconclusive_and_blames_no_node(tmp_path):
    scenario = load_scenario(_scenario(tmp_path, 60.0))
    out = io.StringIO()
    options = LaunchOptions(timeout_s=0.5, handle_signals=False, startup_s=8.0)
    result = asyncio.run(run_fleet(scenario, options, out=out))
    text = out.getvalue()
    assert result.failed == (), text
    assert result.verdict is not None and result.verdict.status == Status.INCONCLUSIVE, text
    assert result.verdict.summary == ("the run ended before the fleet was up (the fleet was "
                                      "not up after 8 s; not alive yet: b): nothing ran to "
                                      "judge"), text
    assert "Traceback" not in text and "KeyboardInterrupt" not in text, text
    assert result.exit_codes["b"] == 0, text
