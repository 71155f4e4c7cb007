"""How close do robots ever get in the paper's cases, next to the model's collision test?

For each paper case in the `rebeca` profile and `rebeca` semantics
(`launch/cX_rebeca.yaml`) this script checks, besides the model's collision
property, a *separation* invariant on the map server's tracked cells:
"no two robots within Chebyshev distance k", for k = 0, 1, 2. The smallest k
that is violated is the closest approach over every reachable state (robots are
0.4 m on 0.255 m cells, so distance ≤ 1 means physical overlap, docs/robots.md §7).
C2a's collision, which RMC and the paper report too, comes at a closest approach
of two cells: the model's shadow box of a diagonal heading is a 0.62 m segment
that reaches into a robot two cells away.

It then re-checks C2a and C2b with every instance-priority order the model
files use, with both max-wait settings and both scan rates: if the state count
never changes, no robot ever waits long enough to back off and the run has one
behaviour (up to the order of commuting same-instant events).

    PYTHONPATH=. python benchmarks/paper_c2_analysis.py [--cases c1a c2a ...]
"""

from __future__ import annotations

import argparse
import itertools
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import yaml

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from twinfleet.checker.driver import CheckOptions, check  # noqa: E402

CASES = ("c1a", "c1b", "c1c", "c2a", "c2b", "c2c")
SEPARATION = ("all(max(abs(a[0] - b[0]), abs(a[1] - b[1])) > {k} "
              "for i, a in enumerate(map_server.cells) for b in map_server.cells[i + 1:] "
              "if a[0] >= 0 and b[0] >= 0)")
PRIORITY_ORDERS = {"3,5,6,4,2": (3, 5, 6, 4, 2), "3,6,5,4,2": (3, 6, 5, 4, 2),
                   "2,3,4,5,6": (2, 3, 4, 5, 6)}
MAX_WAITS = {"1500 each": (1500,) * 5, "1500..3000": (1500, 2000, 2500, 3000, 1500)}


def load_case(case: str) -> dict[str, Any]:
    """The scenario document of `launch/<case>_rebeca.yaml` with an absolute map path."""
    path = ROOT / "twinfleet" / "launch" / f"{case}_rebeca.yaml"
    doc = yaml.safe_load(path.read_text())
    doc["params"]["map"] = str((path.parent / doc["params"]["map"]).resolve())
    return doc


def run(doc: dict[str, Any], workdir: Path) -> Any:
    """Check a scenario document (exhaustive BFS); returns the CheckResult."""
    path = workdir / f"{doc['name']}.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return check(path, CheckOptions())


def robots(doc: dict[str, Any]) -> list[dict[str, Any]]:
    """The robot node entries of a scenario document, in file order."""
    return [n for n in doc["nodes"] if n["class"].endswith(":Robot")]


def closest_approach(case: str, workdir: Path) -> tuple[str, str]:
    """(closest Chebyshev distance, where it first happens) over all reachable states."""
    for k in (0, 1, 2):
        doc = load_case(case)
        doc["properties"] = [{"name": f"separation_gt_{k}", "kind": "invariant",
                              "expr": SEPARATION.format(k=k)}]
        result = run(doc, workdir)
        if result.status == "violated":
            last = result.trace["steps"][-1]
            tracked = last["changed"]["map_server"]
            cells = ", ".join(f"{tuple(c)}d{d}" for c, d in zip(tracked["cells"], tracked["dirs"], strict=True))
            return str(k), f"t={last['time']} ms: {cells}"
    return "> 2", ""


def sweep(case: str, workdir: Path) -> set[int]:
    """State counts of `case` over priority orders × max waits × scan rates."""
    counts = set()
    for (porder, prios), (wname, waits), rate in itertools.product(
            PRIORITY_ORDERS.items(), MAX_WAITS.items(), (100, 140)):
        doc = load_case(case)
        doc["params"]["scan_rate_ms"] = rate
        for node, prio, wait in zip(robots(doc), prios, waits, strict=True):
            node["priority"] = prio
            node["params"]["max_wait_ms"] = wait
            node["params"]["allow_unsafe_speed"] = True
        result = run(doc, workdir)
        print(f"  {case} scan {rate} ms, priorities {porder}, max wait {wname}: "
              f"{result.status}, {result.statistics.states} states", flush=True)
        counts.add((rate, result.statistics.states))
    return counts


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", nargs="+", default=list(CASES), choices=CASES,
                        help="paper cases to analyse (default: all six)")
    parser.add_argument("--no-sweep", action="store_true",
                        help="skip the priority/max-wait/scan-rate sweep of C2a and C2b")
    args = parser.parse_args(argv)
    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        workdir = Path(tmp)
        print("case | model's collision test | states | closest approach (cells) | first at")
        for case in args.cases:
            verdict = run(load_case(case), workdir)
            distance, where = closest_approach(case, workdir)
            print(f"{case} | {verdict.status} | {verdict.statistics.states} | {distance} | {where}",
                  flush=True)
        if not args.no_sweep:
            for case in (c for c in ("c2a", "c2b") if c in args.cases):
                counts = sweep(case, workdir)
                per_rate = {rate: {n for r, n in counts if r == rate} for rate, _ in counts}
                same = all(len(v) == 1 for v in per_rate.values())
                print(f"{case}: state count independent of priorities and max wait: {same} "
                      f"({', '.join(f'{r} ms: {sorted(v)}' for r, v in sorted(per_rate.items()))})")
    print(f"done in {time.perf_counter() - started:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
