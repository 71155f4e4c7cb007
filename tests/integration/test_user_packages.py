"""A user's own packages named `nodes`, `runtime` and `checker`, beside the scenario, run
from another directory: `twinfleet check` and `twinfleet launch` both use the user's
classes and helpers, and no process of either has a top-level `nodes`, `runtime` or
`checker` of ours (`tests/integration/user_project.py` says how the nodes record that).

Before every layer became a sub-package of `twinfleet/`, node processes found
twinfleet's own top-level `nodes` first and `twinfleet launch` of such a project failed.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.integration.itest_support import kill_all, orphaned_nodes, poll
from tests.integration.user_project import (
    LISTENER_MARK,
    PINGER_MARK,
    expected_modules,
    logged_modules,
    write_project,
)
from tests.support import child_env

pytestmark = [pytest.mark.slow, pytest.mark.timeout(90)]

PROPERTIES = "user_classes, user_modules, started, all_heard, no_failure"
CONSOLE_SCRIPT = Path(sys.executable).with_name("twinfleet")


@pytest.fixture
def project(tmp_path: Path) -> Path:
    """The user's project; its scenario is proj/pp.yaml."""
    return write_project(tmp_path / "proj").parent


@pytest.fixture
def elsewhere(tmp_path: Path) -> Path:
    """The working directory of the commands: empty, and not the project's."""
    path = tmp_path / "elsewhere"
    path.mkdir()
    return path


def twinfleet(runner: str, *args: str, cwd: Path, timeout: float
              ) -> subprocess.CompletedProcess[str]:
    """`python -m twinfleet ARGS` or the console script, stderr merged into stdout."""
    head = [sys.executable, "-m", "twinfleet"] if runner == "-m" else [str(CONSOLE_SCRIPT)]
    return subprocess.run([*head, *args], cwd=cwd, env=child_env(), stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, text=True, timeout=timeout, check=False)


RUNNERS = ["-m", pytest.param("script", marks=pytest.mark.skipif(
    not CONSOLE_SCRIPT.exists(), reason="no twinfleet console script beside this Python"))]


@pytest.mark.parametrize("runner", RUNNERS)
def test_check_uses_the_users_packages(project: Path, elsewhere: Path, runner: str) -> None:
    scenario = os.path.relpath(project / "pp.yaml", elsewhere)  # ../proj/pp.yaml
    result = twinfleet(runner, "check", scenario, cwd=elsewhere, timeout=60)
    assert result.returncode == 0, result.stdout
    assert "verdict: HOLDS: every property holds" in result.stdout, result.stdout

    # The states the checker saw, from a trace: reveal.yaml's third_ping fails when the
    # listener has heard the third ping (so the pinger's timer and publication ran).
    trace = elsewhere / "reveal.trace.json"
    reveal = twinfleet(runner, "check", os.path.relpath(project / "reveal.yaml", elsewhere),
                       "--json", "--trace-out", str(trace), cwd=elsewhere, timeout=60)
    out = json.loads(reveal.stdout)
    assert (reveal.returncode, out["verdict"], out["violation"]["property"]) == (
        1, "violated", "third_ping"), reveal.stdout
    states = json.loads(trace.read_text())["initial"]["states"]
    want = expected_modules(project)
    for node, mark in (("pinger", PINGER_MARK), ("listener", LISTENER_MARK)):
        assert states[node]["marker"] == mark
        assert dict(states[node]["modules"]) == want, states[node]
        assert states[node]["strays"] == [], states[node]
    assert not (elsewhere / "out").exists() or not list((elsewhere / "out").iterdir())


def test_launch_uses_the_users_packages(project: Path, elsewhere: Path) -> None:
    scenario = project / "pp.yaml"
    argv = [sys.executable, "-m", "twinfleet", "launch", os.path.relpath(scenario, elsewhere),
            "--timeout", "2"]
    try:
        result = subprocess.run(argv, cwd=elsewhere, env=child_env(), stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True, timeout=60, check=False)
    finally:
        poll(lambda: not orphaned_nodes(), 10)
        leftovers = orphaned_nodes()
        kill_all(leftovers)
    out = result.stdout
    assert not leftovers, out
    assert result.returncode == 0, out
    assert f"[launcher] result: PASSED ({PROPERTIES} hold)" in out, out
    for node in ("pinger", "listener"):
        assert f"[launcher]   {node}: exit code 0 (ok)" in out, out
    assert "[listener] t=" in out and "USER-HEARD data='ping 3'" in out, out
    # Each node process says, at start, which top-level layer-named modules it holds.
    want = expected_modules(project)
    assert logged_modules(out) == {"pinger": (want, ()), "listener": (want, ())}, out
