"""Checker throughput and memory per visited state, on C1a and on a synthetic ring.

By default runs `launch/c1a.yaml` and `launch/c1a_rebeca.yaml` (BFS, to the
end) with three state stores, each in a fresh child process pinned to one core:

- `baseline`: the checker as it was before the compact store (git commit
  ef95c3a, extracted with `git archive`; skipped if git cannot provide it):
  dict of 128-bit digests, a Python array per state for edges, no
  transition cache;
- `exact`: today's checker with `--exact-states` (dict of 128-bit digests);
- `compact`: today's default (64-bit digests stored by id plus an int32
  slot table, int32 parents, CSR edges, a two-generation transition cache,
  interned node states).

`--baseline-rev REV --stores baseline,compact` compares with any earlier
checker the same way (e.g. the commit before a change).

For each it prints transitions/s, store bytes per visited state (what the
visited set, parent records, flags and edges hold), whole-process RSS growth
per visited state (peak RSS during the search minus RSS before it, the
kernel's peak counter reset when the search starts; "end" uses the RSS after
the search instead of the peak: both include every cache, the node code's own
memos and allocator slack, so they are a fixed cost plus the store), the
marginal RSS per state between the first 50 ms sample past half the final
state count and the end of the same run (RSS is page-granular and the
allocator keeps freed memory, so treat it as an estimate),
and the estimated digest-collision probability (n²/2^65 for 64-bit digests,
TLC-style, plus the content hashes that feed them).

    PYTHONPATH=. python benchmarks/checker_throughput.py [--stores baseline,exact,compact]
    PYTHONPATH=. python benchmarks/checker_throughput.py --scenarios launch/c1b.yaml
    PYTHONPATH=. python benchmarks/checker_throughput.py --scenarios launch/c1b_rebeca.yaml@ros
    PYTHONPATH=. python benchmarks/checker_throughput.py --ring --nodes 7 --modulo 3

A scenario written `FILE@SEMANTICS` runs under those message rules instead of
the file's own. "trans/s" is over wall time; "cpu" over this process's CPU
time, which other work on the same core does not inflate. `--json` prints one
JSON line per run instead of the table. The checker aims at >= 20,000 transitions/s
on one core and <= 200 B per visited state (docs/results.md, checker speed).
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
HERE = Path(__file__).resolve().parent
BASELINE_REV = "ef95c3a"
SCENARIOS = ("launch/c1a.yaml", "launch/c1a_rebeca.yaml")
STORES = ("baseline", "exact", "compact")
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))
if str(ROOT) not in sys.path:
    sys.path.insert(1, str(ROOT))

from twinfleet import Context, Node, every, message, subscribe  # noqa: E402


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


def ring_scenario(nodes: int, modulo: int, semantics: str) -> Any:
    """The ring of `nodes` spinners: each ticks and passes a token on; rounds interleave."""
    from twinfleet.runtime.scenario.spec import parse_scenario

    doc = {"name": "bench", "semantics": semantics, "nodes": [
        {"name": f"s{i}", "namespace": f"/s{i}", "class": "checker_throughput:Spinner",
         "params": {"next": f"/s{(i + 1) % nodes}/in", "modulo": modulo,
                    "period_ms": 10 * (1 + i % 2)}}
        for i in range(nodes)],
        "properties": [{"name": "bounded", "kind": "invariant", "expr": f"s0.total < {modulo}"}]}
    return parse_scenario(doc, ROOT / "benchmarks" / "bench.yaml")


# ----------------------------------------------------------------- child


def _rss_now_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def _reset_peak_rss() -> bool:
    """Start the kernel's peak-RSS count (VmHWM, ru_maxrss) afresh; False if it cannot."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        return False
    return True


def _old_graph_bytes(graph: Any) -> int:
    """What the baseline's StateGraph holds (dict of 16-byte digests, arrays per state)."""
    n = len(graph.ids)
    total = sys.getsizeof(graph.ids) + n * sys.getsizeof(b"\0" * 16)
    total += sum(sys.getsizeof(v) for v in graph.ids.values() if v > 256)
    total += sys.getsizeof(graph.parent) + sys.getsizeof(graph.terminal)
    total += sum(sys.getsizeof(b) for b in graph.holds.values())
    if graph.edges is not None:
        total += sys.getsizeof(graph.edges) + sum(sys.getsizeof(a) for a in graph.edges)
    return total


def child(args: argparse.Namespace) -> None:
    """Run one search in this process and print its JSON line."""
    if args.checker_path:
        sys.path.insert(0, args.checker_path)
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[-1]})
    from twinfleet.checker import PropertySet, Search, System
    from twinfleet.checker.driver import load
    from twinfleet.checker.search import peak_rss_mb

    semantics = None
    if args.scenario == "ring":
        scenario = ring_scenario(args.nodes, args.modulo, args.semantics)
    else:
        file, _, semantics = args.scenario.partition("@")
        scenario = load(ROOT / file)
    props = PropertySet.from_scenario(scenario)
    kwargs: dict[str, Any] = {}
    if args.store in ("exact", "compact", "compact-nocache"):
        kwargs["exact_states"] = args.store == "exact"
        kwargs["transition_cache"] = args.store != "compact-nocache"
    if semantics:
        kwargs["semantics"] = semantics
    system = System(scenario, properties=props, **kwargs)
    system.initial()
    gc.collect()
    rss0 = _rss_now_mb()
    # Without the reset, a peak from loading the scenario would hide the search's own.
    fresh_peak = _reset_peak_rss()
    samples: list[tuple[int, float]] = []

    def sample(stats: Any) -> None:
        samples.append((stats.states, _rss_now_mb()))

    search = Search(system, props, progress=sample, progress_interval=0.05)
    start, cpu = time.perf_counter(), time.process_time()
    outcome = search.run("bfs")
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu
    s = outcome.statistics
    store = getattr(search, "store", None)
    n = s.states
    if store is not None:
        store_bytes, collision = store.nbytes(), s.collision_probability
    else:
        store_bytes, collision = _old_graph_bytes(search.graph), n * (n - 1) / 2.0**129
    caches = system.cache_sizes() if hasattr(system, "cache_sizes") else {}
    # Marginal RSS per state over the second half of the search, when the caches are warm.
    half = next(((k, r) for k, r in samples if k >= n // 2), None)
    end = _rss_now_mb()
    # The kernel's RSS counters lag by up to 64 pages per thread: never report a peak below a sample.
    peak = max([peak_rss_mb(), end, *(r for _, r in samples)])
    marginal = None if half is None or n == half[0] else (end - half[1]) * 2**20 / (n - half[0])
    print(json.dumps({
        "benchmark": "checker_throughput", "scenario": args.scenario, "store": args.store,
        "verdict": outcome.status, "states": n, "transitions": s.transitions,
        "depth": s.depth, "seconds": round(wall, 3),
        "transitions_per_s": round(s.transitions / wall), "states_per_s": round(n / wall),
        "transitions_per_cpu_s": round(s.transitions / cpu),
        "store_bytes_per_state": round(store_bytes / n, 1),
        "rss_growth_bytes_per_state": round((peak - rss0) * 2**20 / n),
        "rss_end_growth_bytes_per_state": round((end - rss0) * 2**20 / n),
        "marginal_rss_bytes_per_state": None if marginal is None else round(marginal),
        "marginal_from_state": None if half is None else half[0], "peak_reset": fresh_peak,
        "peak_rss_mb": round(peak, 1),
        "collision_probability": collision,
        "handler_runs": caches.get("handler_runs"), "peak_frontier": getattr(s, "peak_frontier", None),
    }))


# ---------------------------------------------------------------- parent


def _baseline_checker(tmp: str, rev: str) -> str | None:
    """Extract `checker/` at `rev` into `tmp`; None (with a note) if git cannot."""
    try:
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev, "checker"],
                                 capture_output=True, check=True, timeout=60).stdout
        subprocess.run(["tar", "-x", "-C", tmp], input=archive, check=True, timeout=60)
    except (OSError, subprocess.SubprocessError) as exc:
        print(f"baseline {rev} unavailable ({exc}); skipping it", file=sys.stderr)
        return None
    return tmp


def _run_child(scenario: str, store: str, args: argparse.Namespace,
               checker_path: str | None) -> dict[str, Any]:
    cmd = [sys.executable, __file__, "--child", "--scenario", scenario, "--store", store,
           "--nodes", str(args.nodes), "--modulo", str(args.modulo),
           "--semantics", args.semantics]
    if checker_path:
        cmd += ["--checker-path", checker_path]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=3600)
    if proc.returncode != 0:
        raise RuntimeError(f"{scenario} / {store} failed:\n{proc.stderr}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _num(value: int | None) -> str:
    return "-" if value is None else f"{value:,}"


def _table(rows: list[dict[str, Any]]) -> None:
    head = (f"{'scenario':<28}{'store':<16}{'states':>9}{'transitions':>13}{'s':>7}"
            f"{'trans/s':>9}{'cpu':>8}{'store B/st':>11}{'RSS B/st':>10}{'end B/st':>10}{'marg. B/st':>11}"
            f"{'P(collision)':>14}")
    print(head)
    print("-" * len(head))
    for r in rows:
        print(f"{r['scenario']:<28}{r['store']:<16}{r['states']:>9,}{r['transitions']:>13,}"
              f"{r['seconds']:>7.2f}{r['transitions_per_s']:>9,}"
              f"{_num(r.get('transitions_per_cpu_s')):>8}"
              f"{r['store_bytes_per_state']:>11.1f}{r['rss_growth_bytes_per_state']:>10,}"
              f"{_num(r.get('rss_end_growth_bytes_per_state')):>10}"
              f"{_num(r['marginal_rss_bytes_per_state']):>11}"
              f"{r['collision_probability']:>14.1e}")
    by_scenario: dict[str, set[tuple[int, int, str]]] = {}
    for r in rows:
        by_scenario.setdefault(r["scenario"], set()).add((r["states"], r["transitions"],
                                                          r["verdict"]))
    same = all(len(v) == 1 for v in by_scenario.values())
    print(f"\nsame verdict, states and transitions in every store: {'yes' if same else 'NO'}")
    print("RSS B/st: (peak RSS during the search - RSS before it) / states; end: the same with "
          "the RSS after the search; marg.: RSS growth per state from the sample past half "
          "the states to the end")
    for r in rows:
        if not r.get("peak_reset", True):
            print(f"{r['scenario']} / {r['store']}: peak RSS could not be reset; "
                  "RSS B/st may hide the search's own peak")
        if r.get("handler_runs"):
            print(f"{r['scenario']} / {r['store']}: {r['handler_runs']:,} handler runs "
                  f"for {r['transitions']:,} transitions; peak frontier {r['peak_frontier']:,}; "
                  f"marginal from state {_num(r.get('marginal_from_state'))}")


def main() -> None:
    """Run the benchmark (or, with --child, one measurement)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", default=",".join(SCENARIOS),
                    help="comma-separated scenario files (relative to the repository), "
                    "each optionally FILE@ros or FILE@rebeca")
    ap.add_argument("--stores", default=",".join(STORES),
                    help="comma-separated: baseline, exact, compact, compact-nocache")
    ap.add_argument("--baseline-rev", default=BASELINE_REV, help="git revision of the baseline")
    ap.add_argument("--ring", action="store_true", help="run the synthetic ring instead")
    ap.add_argument("--nodes", type=int, default=7, help="ring: spinners on the ring")
    ap.add_argument("--modulo", type=int, default=3, help="ring: counter modulus")
    ap.add_argument("--semantics", default="ros", choices=("ros", "rebeca"), help="ring: rules")
    ap.add_argument("--json", action="store_true", help="print JSON lines, not a table")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--scenario", help=argparse.SUPPRESS)
    ap.add_argument("--store", help=argparse.SUPPRESS)
    ap.add_argument("--checker-path", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args)
        return
    scenarios = ["ring"] if args.ring else args.scenarios.split(",")
    stores = args.stores.split(",")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        old = _baseline_checker(tmp, args.baseline_rev) if "baseline" in stores else None
        for scenario in scenarios:
            for store in stores:
                if store == "baseline" and old is None:
                    continue
                row = _run_child(scenario, store, args, old if store == "baseline" else None)
                rows.append(row)
                if args.json:
                    print(json.dumps(row), flush=True)
    if not args.json:
        _table(rows)


if __name__ == "__main__":
    main()
