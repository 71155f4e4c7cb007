"""Checker throughput on a synthetic model with trivial handlers.

Prints one JSON line: states, transitions, seconds, transitions/s, states/s,
peak RSS and bytes of RSS growth per visited state. The model: N `Spinner`
nodes, each with a 10 or 20 ms timer that bumps a counter modulo M and sends a
message to the next node on a ring, which adds it to a sum modulo M. Timers
fire together every 20 ms, so rounds interleave up to N timers and N
deliveries: many states, each handler a few attribute updates.

    PYTHONPATH=. python benchmarks/checker_throughput.py [--nodes 4] [--modulo 3]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(Path(__file__).resolve().parent)]

from checker import Limits, PropertySet, Search, System  # noqa: E402
from checker.search import peak_rss_mb  # noqa: E402
from runtime import Context, Node, every, message, subscribe  # noqa: E402
from runtime.scenario import parse_scenario  # noqa: E402


@message("twinfleet_bench/Token")
class Token:
    """A ring message."""

    value: int = 0


@dataclass(frozen=True)
class SpinnerParams:
    """Parameters of Spinner."""

    next: str = "/s1"
    modulo: int = 3
    period_ms: int = 10


@dataclass
class SpinnerState:
    """State of Spinner."""

    count: int = 0
    total: int = 0


class Spinner(Node):
    """Ticks every period_ms and passes a token to the next node."""

    Params = SpinnerParams

    def initial_state(self) -> SpinnerState:
        return SpinnerState()

    @every("period_ms")
    def tick(self, ctx: Context) -> None:
        self.state.count = (self.state.count + 1) % self.params.modulo
        ctx.publish(self.params.next, Token(self.state.count))

    @subscribe("in")
    def on_token(self, ctx: Context, msg: Token) -> None:
        self.state.total = (self.state.total + msg.value) % self.params.modulo


def build(nodes: int, modulo: int, semantics: str) -> System:
    """A System for the ring of `nodes` spinners."""
    doc = {"name": "bench", "semantics": semantics, "nodes": [
        {"name": f"s{i}", "namespace": f"/s{i}", "class": "checker_throughput:Spinner",
         "params": {"next": f"/s{(i + 1) % nodes}/in", "modulo": modulo,
                    "period_ms": 10 * (1 + i % 2)}}
        for i in range(nodes)],
        "properties": [{"name": "bounded", "kind": "invariant", "expr": f"s0.total < {modulo}"}]}
    scenario = parse_scenario(doc, ROOT / "benchmarks" / "bench.yaml")
    return System(scenario, monitors=PropertySet.from_scenario(scenario))


def main() -> None:
    """Run the benchmark and print its JSON line."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nodes", type=int, default=7, help="spinners on the ring")
    ap.add_argument("--modulo", type=int, default=3, help="counter modulus")
    ap.add_argument("--semantics", default="ros", choices=("ros", "rebeca"), help="message rules")
    ap.add_argument("--search", default="bfs", choices=("bfs", "dfs"), help="search order")
    ap.add_argument("--max-states", type=int, default=None, help="state limit")
    args = ap.parse_args()
    system = build(args.nodes, args.modulo, args.semantics)
    rss0 = peak_rss_mb()
    start = time.perf_counter()
    outcome = Search(system, system.monitors, Limits(max_states=args.max_states)).run(args.search)
    wall = time.perf_counter() - start
    s = outcome.statistics
    print(json.dumps({
        "benchmark": "checker_throughput", "nodes": args.nodes, "modulo": args.modulo,
        "semantics": args.semantics, "search": args.search, "verdict": outcome.status,
        "states": s.states, "transitions": s.transitions, "seconds": round(wall, 3),
        "transitions_per_s": round(s.transitions / wall), "states_per_s": round(s.states / wall),
        "peak_rss_mb": round(s.peak_rss_mb, 1),
        "rss_bytes_per_state": round((s.peak_rss_mb - rss0) * 2**20 / max(s.states, 1)),
    }))


if __name__ == "__main__":
    main()
