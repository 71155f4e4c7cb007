"""`check --workers N` starts its local Ray cluster only when it can pay, and always stops it.

A small search never imports Ray, even when one of its levels is `--min-width`
wide. A Ctrl-C or SIGTERM while the cluster starts ends the command and leaves no
process of the cluster behind: the processes are found among the descendants of
the command this test started (never by their command line), recorded while it
ran, and must all be gone once it ended. Nothing Ray says reaches the terminal.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from tests.integration.itest_support import _parent, kill_all, poll, spawned_by
from tests.support import child_env
from twinfleet.cli import main as cli

pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]

ROOT = Path(__file__).resolve().parents[2]
SHOWS_RAY = "ray_imported="


def headon_jitter(where: Path) -> Path:
    """headon with latencies of 0-1 ms: 14,444 states, levels of about a hundred worlds."""
    cli(["examples", "--copy", "headon", str(where)])
    path = where / "headon.yaml"
    doc = yaml.safe_load(path.read_text())
    doc.setdefault("check", {})["latency"] = {"default": [0, 1]}
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def test_a_small_search_never_imports_ray(tmp_path: Path) -> None:
    # Its levels reach the given width (so a cluster would start on width alone), but the
    # whole search is smaller than what a cluster's start costs.
    path = headon_jitter(tmp_path)
    code = ("import sys; from twinfleet.cli import main; rc = main(sys.argv[1:]); "
            f"print('{SHOWS_RAY}' + str('ray' in sys.modules)); sys.exit(rc)")
    result = subprocess.run([sys.executable, "-c", code, "check", str(path), "--reduction",
                             "none", "--workers", "2", "--min-width", "100"],
                            capture_output=True, text=True, env=child_env(), cwd=ROOT,
                            timeout=240, check=False)
    assert result.returncode == 1, result  # headon's collision
    assert f"{SHOWS_RAY}False" in result.stdout, result.stdout
    assert "engine: ran in one process: " in result.stdout, result.stdout
    assert "states, under the 50,000 at which Ray's workers start" in result.stdout, result.stdout


def _gone(pid: int) -> bool:
    return _parent(pid) is None  # ended (or a zombie waiting for its parent to reap it)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["ctrl-c", "sigterm"])
def test_a_signal_while_the_cluster_starts_leaves_no_process(tmp_path: Path,
                                                            sig: signal.Signals) -> None:
    path = headon_jitter(tmp_path)
    # --min-width 1: the search waits for its workers, so the signal comes during the start
    proc = subprocess.Popen([sys.executable, "-m", "twinfleet", "check", str(path),
                             "--reduction", "none", "--workers", "2", "--min-width", "1"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=child_env(), cwd=ROOT, start_new_session=True)
    seen: set[int] = set()
    try:
        # `ray start` and at least one process it started (Ray's GCS): the cluster is
        # starting, and no worker can be up yet.
        def starting() -> bool:
            seen.update(spawned_by(proc.pid))
            return len(seen) >= 2 or proc.poll() is not None
        assert poll(starting, timeout=120, interval=0.02), "the cluster never started"
        assert proc.poll() is None, proc.communicate()
        proc.send_signal(sig)
        deadline = time.monotonic() + 120
        while proc.poll() is None and time.monotonic() < deadline:
            seen.update(spawned_by(proc.pid))
            time.sleep(0.02)
        out, err = proc.communicate(timeout=30)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
    try:
        assert poll(lambda: all(_gone(pid) for pid in seen), timeout=10), \
            [pid for pid in seen if not _gone(pid)]
    finally:
        kill_all([pid for pid in seen if not _gone(pid)])
    assert proc.returncode in (130, 143, 2), (proc.returncode, out, err)
    for said in ("Token authentication", "SIGTERM handler", "ray start", "Ray runtime"):
        assert said not in out + err, (out, err)
