"""A passing launch is quiet, and a run asked to stop when settled stops then.

The station system (tests/data/station/settled.yaml: one robot books the one
slot; `a_charging` is an eventually property) is launched with
`--until-settled` and a 20 s timeout: the run ends as soon as the property
holds, saying when it held, and prints one line per node with the counters
that are not zero, not the nodes' full `stopped:` counter lines (`-v` shows
them).
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.support import child_env

pytestmark = [pytest.mark.slow, pytest.mark.timeout(90)]

SETTLED = Path(__file__).resolve().parents[1] / "data" / "station" / "settled.yaml"


def _launch(tmp_path: Path, *flags: str) -> tuple[int, list[tuple[float, str]]]:
    """Run `twinfleet launch` from an empty directory; its exit code and its output lines,
    each with the monotonic time it was read."""
    proc = subprocess.Popen([sys.executable, "-m", "twinfleet", "launch", str(SETTLED), *flags],
                            cwd=tmp_path, env=child_env(), stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, bufsize=1)
    lines = []
    try:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.append((time.monotonic(), line.rstrip("\n")))
        return proc.wait(timeout=30), lines
    finally:
        if proc.poll() is None:
            proc.kill()


def _at(lines: list[tuple[float, str]], text: str) -> float:
    return next(t for t, line in lines if text in line)


def test_until_settled_ends_the_run_when_the_eventually_held_and_it_is_quiet(tmp_path):
    started = time.monotonic()
    code, lines = _launch(tmp_path, "--until-settled")
    text = "\n".join(line for _, line in lines)
    assert code == 0 and "result: PASSED" in text, text
    assert "[launcher] a_charging held at t=" in text, text
    assert "run ended: settled: every eventually property held" in text, text
    assert _at(lines, "run ended: settled") - _at(lines, "a_charging held at") < 1.0, text
    assert time.monotonic() - started < 15, text  # not the scenario's 20 s timeout
    assert "stopped:" not in text, text
    table = [line for _, line in lines if ": exit code 0 (ok)" in line]
    assert len(table) == 2 and all("handled=" in line for line in table), text
    assert not any("=0" in line.split("(ok)")[1] for line in table), table  # no zero counters


def test_verbose_prints_every_counter(tmp_path):
    code, lines = _launch(tmp_path, "--until-settled", "-v")
    text = "\n".join(line for _, line in lines)
    assert code == 0, text
    stopped = [line for _, line in lines if "stopped: received=" in line]
    assert len(stopped) == 2 and all("rejected_forged=0" in s for s in stopped), text
