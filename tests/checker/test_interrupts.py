"""Every way of stopping a command gives its partial summary, then exit 130 (Ctrl-C) or
143 (SIGTERM): real signals to real `twinfleet` processes (issue 37, finding 7)."""

from __future__ import annotations

import contextlib
import json
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.checker.helpers import node, scenario
from tests.checker.tpc import tpc_scenario
from tests.support import ROOT, child_env
from tests.support import wait_for_line as _wait_for_line

pytestmark = pytest.mark.timeout(180)
SLOW = pytest.mark.slow  # a subprocess each: a second or two


@contextlib.contextmanager
def _twinfleet(*args: str) -> Iterator[subprocess.Popen[str]]:
    proc = subprocess.Popen([sys.executable, "-m", "twinfleet", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=child_env(), cwd=ROOT,
                            start_new_session=True)
    try:
        yield proc
    finally:
        with contextlib.suppress(ProcessLookupError):
            proc.kill()
        proc.communicate(timeout=30)


def _wait_for_file(proc: subprocess.Popen[str], path: Path) -> None:
    deadline = time.monotonic() + 60
    while not path.is_file():  # the search's first checkpoint: it is running
        assert proc.poll() is None and time.monotonic() < deadline, proc.poll()
        time.sleep(0.05)


def _endless(tmp_path: Path) -> Path:
    """A counter that never wraps: the search never ends by itself."""
    return scenario(tmp_path, [node("c", "Counter", modulo=0)], name="endless",
                    properties=[{"name": "small", "kind": "invariant", "expr": "c.count >= 0"}])


@SLOW
@pytest.mark.parametrize(("sig", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_check_stops_with_its_summary(tmp_path, sig, code):
    with _twinfleet("check", str(_endless(tmp_path))) as proc:
        _wait_for_line(proc, "[check] states")
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=60)
    assert proc.returncode == code, (out, err)
    assert "verdict: UNKNOWN: interrupted" in out and "states " in out, out


@SLOW
def test_a_quiet_check_prints_its_summary_on_sigterm(tmp_path):
    saved = tmp_path / "endless.ckpt"
    with _twinfleet("check", str(_endless(tmp_path)), "--quiet", "--json", "--checkpoint",
                    str(saved), "--checkpoint-every", "0") as proc:
        _wait_for_file(proc, saved)
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, (out, err)
    record = json.loads(out)
    assert record["verdict"] == "unknown" and record["states"] > 0
    assert record["exit_code"] == 130  # the command's own: SIGTERM is reported as 143


@SLOW
@pytest.mark.parametrize(("sig", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_statistical_prints_the_estimate_so_far_and_writes_its_traces(tmp_path, sig, code):
    path = tpc_scenario(tmp_path, decision_timeout_ms=1)
    out_dir = tmp_path / "traces"
    with _twinfleet("check", str(path), "--statistical", "--simulations", "100000000",
                    "--traces-out", str(out_dir)) as proc:
        _wait_for_line(proc, "simulations")
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=60)
    assert proc.returncode == code, (out, err)
    assert "interrupted" in out.splitlines()[0], out
    assert "atomic" in out and "violating simulation: twinfleet replay" in out, out
    assert sorted(p.name for p in out_dir.iterdir())  # the violating traces are written


@pytest.mark.parametrize(("end", "reason", "code"), [
    ("interrupted", "SIGINT received", 130), ("terminated", "SIGTERM received", 143),
    ("timeout", "timeout after 5 s", 0)])
def test_launch_reports_sigterm_as_143(end, reason, code):
    from twinfleet.runtime.fleet.fleet_result import EndReason, FleetResult

    assert FleetResult("f", "tcp/127.0.0.1:7447", reason, EndReason(end), {}, ()).exit_code == code


@SLOW
@pytest.mark.parametrize(("sig", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_sweep_stops_saying_what_is_cached(tmp_path, sig, code):
    out = tmp_path / "sweep"
    with _twinfleet("sweep", str(_endless(tmp_path)), "--param", "c.modulo=3,0", "--workers",
                    "1", "--out", str(out)) as proc:
        _wait_for_line(proc, "[sweep] 1/2")  # modulo 3 finished; modulo 0 never does
        proc.send_signal(sig)
        out_text, err = proc.communicate(timeout=60)
    assert proc.returncode == code, (out_text, err)
    assert f"interrupted; the finished points are cached under {out / 'points'}" in err
