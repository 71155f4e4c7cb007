"""Load: four publisher processes flood one subscriber process for ~5 s on loopback.

Each publisher sends `LIMIT` samples on a reliable topic and as many on a
best-effort one (bursts of 25 every 10 ms: ~2,500 samples/s per topic each,
~20,000 samples/s into the subscriber). The subscriber must see every reliable
sample in order (zero sequence gaps, nothing dropped by its inbox), best-effort
drops are reported, and the subscriber's resident memory must stay bounded
while it works (a leak of one message per sample would add ~40 MB).
"""

from __future__ import annotations

import asyncio
import io
import json
import re
import time
from pathlib import Path

import pytest
from itest_support import kill_all, node_pid, pick_free_port, processes_mentioning

from twinfleet.runtime.launcher import run_fleet
from twinfleet.runtime.run_record import read_run_record
from twinfleet.runtime.scenario import load_scenario

pytestmark = [pytest.mark.slow, pytest.mark.timeout(120)]

NODES = "tests.integration.reliability_nodes"
PUBLISHERS = 4
LIMIT = 12_500  # per publisher and topic: ~5 s at 2,500 samples/s
RSS_GROWTH_LIMIT_MB = 30.0


def scenario_text() -> str:
    pubs = "\n".join(
        f'  - {{name: p{i}, class: "{NODES}:Flood", '
        f"params: {{period_ms: 10, burst: 25, size: 64, limit: {LIMIT}}}}}"
        for i in range(1, PUBLISHERS + 1))
    return (f"name: soak\nnodes:\n"
            f'  - {{name: sink, class: "{NODES}:Sink", params: {{expected: {PUBLISHERS * LIMIT}}}}}\n'
            f"{pubs}\nlive: {{timeout_s: 60}}\n")


def rss_mb(pid: int) -> float | None:
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return None
    match = re.search(r"^VmRSS:\s+(\d+) kB", status, re.M)
    return int(match.group(1)) / 1024 if match else None


def test_soak_reliable_topics_lose_nothing_and_memory_stays_bounded(tmp_path: Path) -> None:
    path = tmp_path / "soak.yaml"
    path.write_text(scenario_text())
    scenario = load_scenario(path)
    record = tmp_path / "soak.jsonl"
    out = io.StringIO()
    samples: list[tuple[float, float]] = []  # (seconds since the sink started, RSS MB)

    async def sample_rss() -> None:
        pid = None
        while pid is None:
            pid = node_pid(path, "sink")
            await asyncio.sleep(0.05)
        started = time.monotonic()
        while (mb := rss_mb(pid)) is not None:
            samples.append((time.monotonic() - started, mb))
            await asyncio.sleep(0.2)

    async def body() -> object:
        sampler = asyncio.create_task(sample_rss())
        try:
            return await run_fleet(scenario, time_scale=1.0, seed=1, out=out,
                                   listen=f"tcp/127.0.0.1:{pick_free_port()}",
                                   handle_signals=False, run_record=str(record))
        finally:
            sampler.cancel()
            await asyncio.gather(sampler, return_exceptions=True)

    try:
        result = asyncio.run(body())
    finally:
        kill_all(processes_mentioning(str(path)))
    text = out.getvalue()
    assert result.reason == "shutdown requested by sink: soak done", text  # type: ignore[attr-defined]
    events = read_run_record(record)
    stats = next(e for e in events if e["event"] == "node_stats")["stats"]
    sink = stats["sink"]
    done = re.search(r"^\[sink\] t=\d+ soak_done (.*)$", text, re.M)
    assert done is not None, text
    fields = {k: int(v) for k, v in re.findall(r"(\w+)=(\d+)", done.group(1))}
    reliable, fast, out_of_order = fields["reliable"], fields["fast"], fields["out_of_order"]
    duration_s = (fields["last_ms"] - fields["first_ms"]) / 1000
    # RSS once the flood is under way (1 s after the sink started) vs. the peak after that
    steady = [mb for t, mb in samples if t >= 1.0]
    growth = max(steady) - steady[0] if steady else float("nan")
    figures = {"publishers": PUBLISHERS, "duration_s": round(duration_s, 2),
               "reliable": reliable, "best_effort": fast,
               "msgs_per_s": round((reliable + fast) / duration_s),
               "gaps": sink["gaps"], "out_of_order": out_of_order,
               "dropped_keep_last": sink["dropped_keep_last"],
               "dropped_overflow": sink["dropped_overflow"],
               "best_effort_dropped": sink["dropped_best_effort"],
               "rss_mb_start": round(steady[0], 1) if steady else None,
               "rss_mb_max": round(max(steady), 1) if steady else None,
               "rss_growth_mb": round(growth, 1)}
    print("\nsoak figures:", json.dumps(figures))
    assert reliable == PUBLISHERS * LIMIT
    assert out_of_order == 0
    assert sink["gaps"] == 0 and sink["dropped_keep_last"] == 0 and sink["dropped_overflow"] == 0
    assert sink["dropped_undecodable"] == 0
    assert all(stats[f"p{i}"]["published"] == 2 * LIMIT for i in range(1, PUBLISHERS + 1))
    assert fast + sink["dropped_best_effort"] <= PUBLISHERS * LIMIT
    assert len(steady) >= 5, samples
    assert growth < RSS_GROWTH_LIMIT_MB, figures
    assert not processes_mentioning(str(path))
