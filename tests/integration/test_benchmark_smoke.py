"""The runtime overhead benchmark still runs end to end (tiny windows; figures not asserted)."""

from __future__ import annotations

import json
import subprocess
import sys
from typing import Any

import pytest
from itest_support import ROOT, child_env

pytestmark = [pytest.mark.slow, pytest.mark.timeout(90)]


def _run() -> tuple[subprocess.CompletedProcess[str], dict[str, Any]]:
    result = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "runtime_overhead.py"), "--pairs", "1",
         "--sizes", "64", "--rounds", "300", "--chunk", "100", "--warmup", "50", "--floods", "1",
         "--flood-s", "0.2", "--child-timeout", "30"],
        capture_output=True, text=True, timeout=80, env=child_env(), cwd=ROOT, check=False)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    assert "twinfleet vs raw (median of 1 pairs)" in result.stdout
    (line,) = [ln for ln in result.stdout.splitlines() if ln.startswith('{"summary"')]
    return result, json.loads(line)["summary"]["64"]


def test_runtime_overhead_benchmark_smoke() -> None:
    result, summary = _run()
    if summary["twinfleet"]["gaps"] and not summary["twinfleet"]["lost"]:
        # Seen once in a full run beside the other test worker's CPU-bound checks: a
        # sequence gap on the echo node with every message received. Measured once more,
        # so that only a gap that repeats fails the test.
        print(f"gaps with nothing lost, measuring again: {summary['twinfleet']}")
        result, summary = _run()
    for impl in ("raw", "asyncio", "twinfleet"):
        row = summary[impl]
        assert row["rounds"] > 0 and row["msg_per_s"] > 0, (impl, row)
        assert row["lost"] == 0 and row["gaps"] == 0, (impl, row)
    assert "64 B latency p50" in result.stdout and "64 B throughput" in result.stdout  # verdict
    assert summary["twinfleet"]["wire_bytes"] > 64  # the envelope travels with the payload
