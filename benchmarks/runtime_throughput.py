"""Receive throughput of the Zenoh → asyncio hand-off: coalesced vs one wake-up per sample.

Two processes on loopback: this one (an embedded Zenoh router plus the
receiving session and its asyncio loop) and a publisher subprocess that puts
N samples back to back with congestion control BLOCK. Modes, interleaved over
`--runs` rounds in the same run:

* ``coalesced``  — `runtime.host.zenoh_transport.Handoff`: append to a deque, one
  `call_soon_threadsafe` per burst (what `ZenohTransport` does);
* ``per_sample`` — one `loop.call_soon_threadsafe(handler, payload)` per sample.

The handler on the loop only counts. Rate = received / (last − first arrival).
Prints one JSON line per measurement, then a JSON summary (medians).

    python benchmarks/runtime_throughput.py [--count 100000] [--size 64] [--runs 3]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import statistics
import sys
import time
from pathlib import Path

import zenoh

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import contextlib

from twinfleet.runtime.fleet.launcher import free_port  # noqa: E402
from twinfleet.runtime.host.zenoh_transport import Handoff, zenoh_config  # noqa: E402

PUBLISHER = """
import sys, time, zenoh
sys.path.insert(0, sys.argv[4])
from twinfleet.runtime.host.zenoh_transport import zenoh_config
endpoint, key, count, size = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[5])
with zenoh.open(zenoh_config(connect=[endpoint])) as s:
    pub = s.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
    deadline = time.monotonic() + 10
    while not pub.matching_status and time.monotonic() < deadline:
        time.sleep(0.01)
    payload = bytes(size)
    for _ in range(count):
        pub.put(payload)
    time.sleep(0.5)
    pub.undeclare()
"""


class Counter:
    """Counts samples on the loop and timestamps the first and last."""

    def __init__(self, expected: int, done: asyncio.Event) -> None:
        self.expected, self.done = expected, done
        self.n = 0
        self.first = self.last = 0.0

    def on_loop(self, payload: bytes) -> None:
        now = time.perf_counter()
        if self.n == 0:
            self.first = now
        self.n += 1
        self.last = now
        if self.n >= self.expected:
            self.done.set()


async def measure(session: zenoh.Session, endpoint: str, mode: str, key: str,
                  count: int, size: int) -> dict[str, object]:
    """Receive `count` samples through `mode` and return the measured rate."""
    loop = asyncio.get_running_loop()
    done = asyncio.Event()
    counter = Counter(count, done)
    handoff = Handoff(loop)
    if mode == "coalesced":
        def callback(sample: zenoh.Sample) -> None:
            handoff.push(counter.on_loop, sample.payload.to_bytes())
    else:
        def callback(sample: zenoh.Sample) -> None:
            loop.call_soon_threadsafe(counter.on_loop, sample.payload.to_bytes())
    sub = session.declare_subscriber(key, callback)
    root = str(Path(__file__).resolve().parent.parent)
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-c", PUBLISHER, endpoint, key, str(count), root, str(size))
    with contextlib.suppress(TimeoutError):
        await asyncio.wait_for(done.wait(), timeout=120)
    await proc.wait()
    sub.undeclare()
    elapsed = counter.last - counter.first
    rate = (counter.n - 1) / elapsed if elapsed > 0 else 0.0
    return {"mode": mode, "size": size, "sent": count, "received": counter.n,
            "lost": count - counter.n, "msg_per_s": round(rate),
            "wakeups": handoff.wakeups if mode == "coalesced" else counter.n}


async def main_async(args: argparse.Namespace) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    session = zenoh.open(zenoh_config(listen=[endpoint], mode="router"))
    results: dict[str, list[int]] = {"coalesced": [], "per_sample": []}
    try:
        for run in range(args.runs):
            for mode in ("coalesced", "per_sample"):
                row = await measure(session, endpoint, mode, f"bench/{mode}/{run}",
                                    args.count, args.size)
                print(json.dumps({"run": run, **row}), flush=True)
                results[mode].append(int(row["msg_per_s"]))  # type: ignore[arg-type]
    finally:
        session.close()
    med = {mode: statistics.median(v) for mode, v in results.items()}
    print(json.dumps({"summary": "median msg/s", **med,
                      "ratio_coalesced_over_per_sample": round(med["coalesced"] / med["per_sample"], 2)
                      if med["per_sample"] else None}), flush=True)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--count", type=int, default=100_000, help="samples per measurement")
    p.add_argument("--size", type=int, default=64, help="payload bytes")
    p.add_argument("--runs", type=int, default=3, help="interleaved rounds of both modes")
    asyncio.run(main_async(p.parse_args()))


if __name__ == "__main__":
    main()
