"""Discretization study: the paper's case on finer and coarser grids, same node code.

Settings (from one base case, default C1a):

    paper      50×50 cells of 0.255 m, the paper's scan period (the launch files as they are)
    fine       100×100 cells of 0.1275 m, same scan period (Eq. 1 then fails for fast robots)
    fine-scan  100×100 cells of 0.1275 m, scan period halved (Eq. 1 holds again)
    coarse     25×25 cells of 0.51 m (Eq. 2 fails: 0.51 ≥ 0.4/√2)

Each is checked in both profiles (`cX.yaml`: fixed + ros semantics,
`cX_rebeca.yaml`: rebeca + rebeca semantics) with a state and time limit.
Generated maps and scenarios go to --out (not maps/). Prints one line per
(setting, profile) and writes the rows as JSON.

    PYTHONPATH=. python benchmarks/agreement_discretization.py [--case c1a]
        [--max-states 1000000] [--max-time 300] [--out out/discretization]
"""

from __future__ import annotations

import argparse
import json
import sys
from fractions import Fraction
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from twinfleet.robots.discretization import (  # noqa: E402
    cell_rules,
    check_setting,
    scale_map,
    scale_scenario,
)
from twinfleet.runtime.scenario.spec import ScenarioError, load_scenario  # noqa: E402

SETTINGS = (  # name, factor, scan period multiplier
    ("paper", Fraction(1), 1),
    ("fine", Fraction(2), 1),
    ("fine-scan", Fraction(2), Fraction(1, 2)),
    ("coarse", Fraction(1, 2), 1),
)


def build(case: str, out: Path) -> list[tuple[str, Path]]:
    """Write every setting's map and scenarios; return (setting, scenario) pairs."""
    pairs = []
    base_map = ROOT / "twinfleet" / "maps" / "map50.yaml"
    for name, factor, scan_mult in SETTINGS:
        for variant in (case, f"{case}_rebeca"):
            src = ROOT / "twinfleet" / "launch" / f"{variant}.yaml"
            if factor == 1 and scan_mult == 1:
                pairs.append((name, src))
                continue
            tag = str(factor).replace("/", "over")
            map_yaml = scale_map(base_map, factor, out / f"map50_x{tag}.yaml")
            scan = int(load_scenario(src).nodes[0].params.scan_rate_ms * scan_mult)
            dst = out / f"{variant}_{name}.yaml"
            scale_scenario(src, factor, map_yaml, dst, scan_rate_ms=scan,
                           name=f"{variant}_{name}".replace("-", "_"))
            pairs.append((name, dst))
    return pairs


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--case", default="c1a", help="base case: c1a … c2c (default: %(default)s)")
    p.add_argument("--max-states", type=int, default=1_000_000)
    p.add_argument("--max-time", type=float, default=300.0, help="seconds per check")
    p.add_argument("--only", default=None, help="comma-separated settings to run")
    p.add_argument("--out", default=str(ROOT / "out" / "discretization"))
    args = p.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    only = set(args.only.split(",")) if args.only else None
    print(f"{'setting':<10} {'cells':>7} {'R m':>6} {'scan':>4} {'Eq.2':>5} {'Eq.1 broken':>12} "
          f"{'hidden cm':>9} {'profile':<7} {'sem':<6} {'verdict':<24} {'states':>8} "
          f"{'trans':>9} {'time s':>7} {'depth':>5} {'MB':>5}")
    rows = []
    for setting, scenario in build(args.case, out):
        if only and setting not in only:
            continue
        try:
            rules = cell_rules(scenario)
            sc = load_scenario(scenario)
        except (ScenarioError, ValueError) as exc:
            print(f"{setting:<10} invalid: {exc}", flush=True)
            rows.append({"setting": setting, "scenario": str(scenario), "invalid": str(exc)})
            continue
        res = check_setting(setting, scenario, max_states=args.max_states,
                            max_time_s=args.max_time, trace_dir=out / "traces")
        cells = "x".join(str(n) for n in _shape(sc))
        scan = sc.nodes[0].params.scan_rate_ms
        hidden = f"{rules.hidden_edge_m * 100:.1f}/{rules.hidden_diagonal_m * 100:.1f}"
        verdict = {"holds": "holds", "violated": f"violated ({res.detail})"}.get(
            res.status, "unknown (limit)" if "reached" in res.detail else f"unknown ({res.detail})")
        print(f"{setting:<10} {cells:>7} {rules.cell_m:>6.4f} {scan:>4} "
              f"{'ok' if rules.cell_rule is None else 'FAIL':>5} "
              f"{','.join(rules.unsafe_robots) or '-':>12} {hidden:>9} {res.profile:<7} "
              f"{res.semantics:<6} {verdict:<24} {res.states:>8,} {res.transitions:>9,} "
              f"{res.time_s:>7.1f} {res.depth:>5} {res.extra.get('peak_mb', 0):>5.0f}", flush=True)
        rows.append({"setting": setting, "scenario": str(scenario), "cells": cells,
                     "cell_m": rules.cell_m, "scan_ms": scan, "eq2_holds": rules.cell_rule is None,
                     "eq2_bound_m": round(rules.bound_m, 4), "eq1_broken_by": rules.unsafe_robots,
                     "hop_ms": dict(rules.hop_ms), "hidden_edge_m": round(rules.hidden_edge_m, 4),
                     "hidden_diagonal_m": round(rules.hidden_diagonal_m, 4),
                     "profile": res.profile, "semantics": res.semantics, "status": res.status,
                     "detail": res.detail, "states": res.states, "transitions": res.transitions,
                     "time_s": round(res.time_s, 2), "depth": res.depth, **res.extra})
    (out / "discretization.json").write_text(json.dumps(rows, indent=1) + "\n")
    print(f"# wrote {out / 'discretization.json'}")
    return 0


def _shape(scenario) -> tuple[int, int]:  # noqa: ANN001
    from twinfleet.nodes.mapfile import load_map

    return load_map(scenario.node("map_server").params.map).shape


if __name__ == "__main__":
    sys.exit(main())
