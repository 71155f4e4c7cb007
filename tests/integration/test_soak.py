"""Load: four publisher processes flood one subscriber process on loopback, in two rounds.

Each publisher sends `LIMIT` samples on a reliable topic and as many on a
best-effort one (bursts of 25 every 10 ms: ~2,500 samples/s per topic each,
~20,000 samples/s into the subscriber), half in each round; the second round
starts when the subscriber has received all of the first. The subscriber must
see every reliable sample in order (zero sequence gaps, nothing dropped by its
inbox), best-effort drops are reported, and its memory must not grow from the
end of the first round to the end of the second.

Why rounds: while the flood outpaces the subscriber (it does on a slow or busy
machine), its inbox (KEEP_LAST 100,000) holds the backlog, so its peak memory
measures the machine's speed, not a leak. At the end of a round the backlog is
gone; a second round of equal size then reuses the memory the first one took,
while a leak of one object per sample would add 50,000 live objects (and ~20 MB).
"""

from __future__ import annotations

import asyncio
import io
import json
import re
from pathlib import Path

import pytest
from itest_support import fleet_nodes, kill_all, pick_free_port

from twinfleet.runtime.fleet.launcher import LaunchOptions, run_fleet
from twinfleet.runtime.fleet.run_record import read_run_record
from twinfleet.runtime.scenario.spec import load_scenario

pytestmark = [pytest.mark.slow, pytest.mark.timeout(120)]

NODES = "tests.integration.reliability_nodes"
PUBLISHERS = 4
LIMIT = 12_500  # per publisher and topic: ~5 s at 2,500 samples/s
ROUNDS = 2
BLOCKS_GROWTH_LIMIT = 10_000  # live Python objects; a leak of one per sample: >= 50,000
RSS_GROWTH_LIMIT_MB = 12.0  # a leak of one message per sample: ~20 MB


def scenario_text() -> str:
    pubs = "\n".join(
        f'  - {{name: p{i}, class: "{NODES}:Flood", '
        f"params: {{period_ms: 10, burst: 25, size: 64, limit: {LIMIT}, rounds: {ROUNDS}}}}}"
        for i in range(1, PUBLISHERS + 1))
    return (f"name: soak\nnodes:\n"
            f'  - {{name: sink, class: "{NODES}:Sink", '
            f"params: {{expected: {PUBLISHERS * LIMIT}, rounds: {ROUNDS}}}}}\n"
            f"{pubs}\nlive: {{wall_timeout_s: 60}}\n")


def logged(text: str, event: str) -> list[dict[str, int]]:
    """The integer fields of each ``[sink] t=... <event> k=v ...`` line."""
    return [{k: int(v) for k, v in re.findall(r"(\w+)=(-?\d+)", fields)}
            for fields in re.findall(rf"^\[sink\] t=\d+ {event} (.*)$", text, re.M)]


def test_soak_reliable_topics_lose_nothing_and_memory_stays_bounded(tmp_path: Path) -> None:
    path = tmp_path / "soak.yaml"
    path.write_text(scenario_text())
    scenario = load_scenario(path)
    record = tmp_path / "soak.jsonl"
    out = io.StringIO()

    async def body() -> object:
        options = LaunchOptions(time_scale=1.0, seed=1,
                                listen=f"tcp/127.0.0.1:{pick_free_port()}",
                                handle_signals=False, run_record=str(record))
        return await run_fleet(scenario, options, out=out)

    try:
        result = asyncio.run(body())
    finally:
        kill_all(fleet_nodes())
    text = out.getvalue()
    assert result.reason == "shutdown requested by sink: soak done", text  # type: ignore[attr-defined]
    events = read_run_record(record)
    stats = next(e for e in events if e["event"] == "node_stats")["stats"]
    sink = stats["sink"]
    done, rounds = logged(text, "soak_done"), logged(text, "round_done")
    assert len(done) == 1 and [r["round"] for r in rounds] == list(range(1, ROUNDS + 1)), text
    fields = done[0]
    reliable, fast, out_of_order = fields["reliable"], fields["fast"], fields["out_of_order"]
    duration_s = (fields["last_ms"] - fields["first_ms"]) / 1000
    first, last = rounds[0], rounds[-1]
    rss_growth_mb = (last["rss_kb"] - first["rss_kb"]) / 1024
    blocks_growth = last["blocks"] - first["blocks"]
    figures = {"publishers": PUBLISHERS, "duration_s": round(duration_s, 2),
               "reliable": reliable, "best_effort": fast,
               "msgs_per_s": round((reliable + fast) / duration_s),
               "gaps": sink["gaps"], "out_of_order": out_of_order,
               "dropped_keep_last": sink["dropped_keep_last"],
               "dropped_overflow": sink["dropped_overflow"],
               "best_effort_dropped": sink["dropped_best_effort"],
               "rss_mb_by_round": [round(r["rss_kb"] / 1024, 1) for r in rounds],
               "blocks_by_round": [r["blocks"] for r in rounds],
               "rss_growth_mb": round(rss_growth_mb, 1), "blocks_growth": blocks_growth}
    print("\nsoak figures:", json.dumps(figures))
    assert reliable == PUBLISHERS * LIMIT
    assert out_of_order == 0
    assert sink["gaps"] == 0 and sink["dropped_keep_last"] == 0 and sink["dropped_overflow"] == 0
    assert sink["dropped_undecodable"] == 0
    assert all(stats[f"p{i}"]["published"] == 2 * LIMIT for i in range(1, PUBLISHERS + 1))
    assert fast + sink["dropped_best_effort"] <= PUBLISHERS * LIMIT
    assert blocks_growth < BLOCKS_GROWTH_LIMIT, figures
    assert rss_growth_mb < RSS_GROWTH_LIMIT_MB, figures
    assert not fleet_nodes()
