"""`check` names `trace show`, and `trace show` of an rclpy counterexample: a step's state change names the attributes
that changed (`attrs.sent 1 -> 2`), not the node's whole attribute list before and after."""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

import pytest

from tests.rclpy.oracle import in_process_env
from twinfleet.cli import main

pytestmark = pytest.mark.timeout(60)

in_process_env()


def _run(*argv: str) -> tuple[int, str]:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(list(argv))
    return code, out.getvalue()


def test_a_state_change_shows_the_attributes_that_changed(tmp_path: Path) -> None:
    scenario = tmp_path / "few.yaml"
    scenario.write_text("name: few\nnodes:\n  - {name: talker, class: 'chatter:Talker'}\n"
                        "properties:\n  - {kind: invariant, name: few, expr: 'talker.sent < 2'}\n")
    path = tmp_path / "few.trace.json"
    code, out = _run("check", str(scenario), "--trace-out", str(path))
    assert code == 1, out
    assert f"read it step by step: twinfleet trace show {path}" in out.splitlines()
    code, out = _run("trace", "show", str(path))
    assert code == 0
    changes = [line.strip() for line in out.splitlines()
               if line.strip().startswith("state talker:")]
    assert changes[-1] == "state talker: attrs.sent 1 -> 2", changes


def test_a_suspended_callbacks_snapshots_show_as_their_length(tmp_path: Path) -> None:
    """A coroutine callback suspended in an await keeps its arguments and start state as
    snapshot bytes: `trace show` gives their length, not hundreds of hex digits."""
    scenario = Path(__file__).parent / "programs" / "relay_sloppy.yaml"
    path = tmp_path / "sloppy.trace.json"
    code, out = _run("check", str(scenario), "--trace-out", str(path))
    assert code == 1, out
    code, out = _run("trace", "show", str(path))
    assert code == 0
    tasks = [line for line in out.splitlines() if "tasks [" in line]
    assert tasks and all("'start': <" in line and " bytes>" in line for line in tasks), tasks
    assert not re.search(r"[0-9a-f]{40}", out), out
