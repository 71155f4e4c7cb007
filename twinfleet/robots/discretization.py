"""Discretization study: the same node code on a finer (or coarser) grid.

The robot and map-server code take every length in metres from the map's
resolution, so a finer discretization needs no code change, only a finer map
and a scenario whose cells are scaled: `scale_map` resamples a ROS map by a
factor (2 → every cell becomes 2×2 cells of half the size; 1/2 → 2×2 blocks
merge, an obstacle pixel wins), and `scale_scenario` writes a scenario file
beside it with starts and goals scaled and, optionally, another scan period.
The resulting file runs both in the checker and live.

`cell_rules` evaluates the paper's two discretization rules for a setting:
Eq. 2, CELL_WIDTH < ROBOT_LENGTH/√2 (`nodes.motion.check_cell_size_rule`),
and Eq. 1, hop time > 2 × scan period, per robot
(`nodes.motion.check_scan_rate_rule`), plus the deepest overlap a hop can
hide from a test that only looks at cell poses (`hidden_overlap_m`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Any, final

import numpy as np
import yaml

from twinfleet.checker.driver import CheckOptions, check
from twinfleet.nodes.mapfile import load_map, save_map
from twinfleet.nodes.motion import check_cell_size_rule, check_scan_rate_rule, hop_time_ms
from twinfleet.nodes.profile import profile_named
from twinfleet.robots.timing import map_server, robot_profile
from twinfleet.runtime.contract.kinds import Status
from twinfleet.runtime.scenario.spec import load_scenario


def scale_map(src_yaml: str | Path, factor: Fraction, out_yaml: str | Path) -> Path:
    """Write a resampled copy of a map: `factor` 2 halves the cell size, 1/2 doubles it.

    Refining repeats every pixel factor×factor times (the occupancy is exactly
    the same region); coarsening takes the darkest pixel of each block, so a
    cell is an obstacle if any part of it was. Origin is kept.

    Returns:
        The YAML path written.
    """
    src = load_map(src_yaml)
    gray = src.gray
    if factor >= 1:
        if factor.denominator != 1:
            raise ValueError(f"refinement factor must be an integer, got {factor}")
        k = int(factor)
        img = np.repeat(np.repeat(gray, k, axis=0), k, axis=1)
    else:
        if factor.numerator != 1:
            raise ValueError(f"coarsening factor must be 1/k, got {factor}")
        k = factor.denominator
        rows, cols = (gray.shape[0] // k) * k, (gray.shape[1] // k) * k
        img = gray[:rows, :cols].reshape(rows // k, k, cols // k, k).min(axis=(1, 3))
    out = Path(out_yaml)
    out.parent.mkdir(parents=True, exist_ok=True)
    resolution = src.resolution / float(factor)
    save_map(out, img.astype(np.uint8), resolution, src.origin,
             f"twinfleet: {Path(src_yaml).name} resampled by {factor}")
    return out


def scale_cell(cell: Any, factor: Fraction) -> list[int]:
    """A cell index of the original grid on the resampled grid (×2 refines, //2 coarsens)."""
    return [int(math.floor(c * factor)) for c in cell]


def scale_scenario(src: str | Path, factor: Fraction, map_yaml: str | Path, out: str | Path, *,
                   scan_rate_ms: int | None = None, name: str | None = None) -> Path:
    """Write a copy of a scenario for the resampled map: starts/goals scaled, map replaced.

    Robots whose speed then breaks Eq. 1 get `allow_unsafe_speed: true` so that
    the setting can still be checked (the study reports which).

    Args:
        src: the original scenario file.
        factor: the map's resampling factor.
        map_yaml: the resampled map (the new scenario names it relative to itself).
        out: the scenario file to write.
        scan_rate_ms: another scan period for every node (default: keep).
        name: the new scenario's name (default: `<name>_x<factor>`).
    """
    doc = yaml.safe_load(Path(src).read_text())
    out = Path(out)
    doc["name"] = name or f"{doc.get('name', Path(src).stem)}_x{str(factor).replace('/', 'over')}"
    doc.pop("fleet", None)
    common = doc.setdefault("params", {})
    common["map"] = str(Path(map_yaml).resolve().relative_to(out.parent.resolve()))
    if scan_rate_ms is not None:
        common["scan_rate_ms"] = scan_rate_ms
    res = load_map(map_yaml).resolution
    scan = int(common.get("scan_rate_ms", 100))
    profile = profile_named(common.get("profile", "fixed"))
    for node in doc["nodes"]:
        params = node.get("params") or {}
        for key in ("start", "goal"):
            if key in params:
                params[key] = scale_cell(params[key], factor)
        if "speed" in params and check_scan_rate_rule(float(params["speed"]), res,
                                                      int(params.get("scan_rate_ms", scan)),
                                                      profile):
            params["allow_unsafe_speed"] = True
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(f"# Generated by robots.discretization from {Path(src).name}: map resampled "
                   f"by {factor}, cells scaled.\n" + yaml.safe_dump(doc, sort_keys=False))
    return out


def hidden_overlap_m(step_m: float, robot_length: float) -> float:
    """How deep two robots can overlap during one hop without any sampled pose overlapping.

    Robots as discs of diameter L (the rotation-free reading of Eq. 2); one hop moves one
    robot by `step_m` while the other stands still (hops are atomic events). Another
    robot's centre at distance just over L from both end poses lies at distance
    sqrt(L² − (s/2)²) from the hop's midpoint; the overlap missed there is
    L − sqrt(L² − (s/2)²). For s ≥ 2L a robot can jump clean through another.
    """
    half = step_m / 2
    if half >= robot_length:
        return robot_length
    return robot_length - math.sqrt(robot_length ** 2 - half ** 2)


@final
@dataclass(frozen=True, slots=True)
class Rules:
    """The paper's discretization rules for one setting."""

    cell_m: float
    bound_m: float
    cell_rule: str | None  # None: Eq. 2 holds
    unsafe_robots: tuple[str, ...]  # robots breaking Eq. 1
    hop_ms: tuple[tuple[str, int], ...]
    hidden_edge_m: float
    hidden_diagonal_m: float


def cell_rules(scenario_path: str | Path) -> Rules:
    """Eq. 2 and Eq. 1 for a scenario, and the overlap a hop can hide."""
    sc = load_scenario(scenario_path)
    server = map_server(sc)
    res = server and load_map(server.map).resolution
    if not res:
        raise ValueError(f"{scenario_path}: no map")
    length, unsafe, hops = 0.4, [], []
    for cfg in sc.nodes:
        p = cfg.params
        if hasattr(p, "speed"):
            length = p.robot_length
            prof = profile_named(p.profile)
            hops.append((cfg.name, hop_time_ms(p.speed, False, res, prof)))
            if check_scan_rate_rule(p.speed, res, p.scan_rate_ms, prof):
                unsafe.append(cfg.name)
    return Rules(res, length / math.sqrt(2), check_cell_size_rule(res, length), tuple(unsafe),
                 tuple(hops), hidden_overlap_m(res, length),
                 hidden_overlap_m(math.sqrt(2) * res, length))


@final
@dataclass(slots=True)
class StudyResult:
    """One checker run of one setting."""

    setting: str
    scenario: str
    semantics: str
    profile: str
    status: Status
    detail: str
    states: int
    transitions: int
    time_s: float
    depth: int
    extra: dict[str, Any] = field(default_factory=dict)


def check_setting(setting: str, scenario: str | Path, *, max_states: int | None,
                  max_time_s: float | None, trace_dir: Path | None = None) -> StudyResult:
    """Check a setting's scenario (its own profile and semantics) within the limits."""
    sc = load_scenario(scenario)
    trace = None if trace_dir is None else str(trace_dir / f"{sc.name}.trace.json")
    started = time.monotonic()
    result = check(scenario, CheckOptions(max_states=max_states, max_time_s=max_time_s,
                                          trace_out=trace))
    s = result.statistics
    detail = result.violation.property if result.violation is not None else result.reason
    out = StudyResult(setting, str(scenario), result.semantics, robot_profile(sc), result.status, detail,
                      s.states, s.transitions, time.monotonic() - started, s.depth,
                      {"peak_mb": round(s.peak_rss_mb)})
    if result.violation is not None:
        out.extra["violation"] = result.violation.message
        out.extra["trace"] = result.trace_path
    return out
