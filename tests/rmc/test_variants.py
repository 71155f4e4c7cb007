"""More cases than the paper's six: our `rebeca` system against RMC on variants of the model.

Each variant changes only what a case of the model's `main` sets (speed, max wait,
instance priority per robot, `LASERSCAN_RATE`). The RMC figures below come from RMC run
on the model so edited, with the build `tests/data/rmc/README.md` names (docs/results.md).
Exhaustive cases are compared with our breadth-first counts (order-free);
violating cases with our search in RMC's order (`tests/rmc/rmc_order.py`).
"""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from tests.rmc import adapter, rmc_order
from tests.rmc.follower import DATA, follow
from tests.rmc.rmc_trace import read_trace
from twinfleet.checker.driver import CheckOptions, check

pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]

ROOT = Path(__file__).resolve().parents[2]
#: The `main` of the model's latest version: not a paper case (speed, max wait, priority).
HEAD_MAIN = ((0.6, 1500, 3), (0.7, 2000, 6), (0.7, 2500, 5), (0.7, 3000, 4), (0.4, 1500, 2))


def variant(tmp_path: Path, base: str, scan: int, robots=None) -> Path:
    """`launch/<base>_rebeca.yaml` with another scan period and (speed, wait, priority)s."""
    path = ROOT / "twinfleet" / "launch" / f"{base}_rebeca.yaml"
    doc = yaml.safe_load(path.read_text())
    doc["params"]["map"] = str((path.parent / doc["params"]["map"]).resolve())
    doc["params"]["scan_rate_ms"] = scan
    nodes = [n for n in doc["nodes"] if n["class"].endswith(":Robot")]
    for node, (speed, wait, prio) in zip(nodes, robots or (), strict=False):
        node["params"].update(speed=speed, max_wait_ms=wait, allow_unsafe_speed=True)
        node["priority"] = prio
    for node in nodes:
        node["params"]["allow_unsafe_speed"] = True
    out = tmp_path / f"{base}_{scan}.yaml"
    out.write_text(yaml.safe_dump(doc, sort_keys=False))
    return out


@pytest.mark.parametrize(
    ("base", "scan", "robots", "states", "transitions"),
    [
        ("c1a", 100, HEAD_MAIN, 14_171, 32_792),  # the model's comment says 14,746 / 33,367
        ("c1b", 140, None, 14_351, 33_217),
        ("c1b", 140, [(0.3, 200, 3), (0.3, 200, 6), (0.3, 200, 5), (0.3, 200, 4), (0.7, 200, 2)],
         14_351, 33_217),  # nobody waits, so the max wait changes nothing
    ],
)
def test_exhaustive_variants_have_rmcs_counts(tmp_path, base, scan, robots, states, transitions):
    result = check(variant(tmp_path, base, scan, robots), CheckOptions())
    assert result.status == "holds"
    assert (result.statistics.states, result.rmc_transitions) == (states, transitions)


@pytest.mark.parametrize(
    ("base", "states", "transitions"),
    [("c2a", 3_909, 8_809), ("c2c", 2_176, 4_898)],
)
def test_violating_variants_at_scan_100_have_rmcs_counts_in_rmcs_order(tmp_path, base, states,
                                                                       transitions):
    system, world = adapter.build(variant(tmp_path, base, 100))
    counts = rmc_order.search(system, world, rmc_order.collision_or_livelock)
    assert counts.violated
    assert (counts.states, counts.transitions) == (states, transitions)


#: Detour cases (tests/data/rmc/README.md): trace file, base case, scan, robots, RMC's counts.
DETOURS = {
    "c2c-scan100-wait100-detour": (
        "c2c", 100, [(0.9, 100, 3), (0.8, 100, 6), (0.7, 100, 5), (0.6, 100, 4), (1.0, 100, 2)],
        545, 6_292, 13_936),
    "fast-scan140-wait100-detour": (
        "c2c", 140, [(1.0, 100, 2), (1.0, 100, 3), (1.0, 100, 4), (1.0, 100, 5), (1.0, 100, 6)],
        1_198, 18_383, 41_021),
}


def detour_progress(system, world) -> bool:
    """The assertion of the detour traces: a robot is two waypoints along a back-off plan."""
    states = adapter.node_states(system, world)
    return any(len(s.targets) > 1 and s.move_idx >= 2 for n, s in states.items() if n != "map_server")


@pytest.mark.parametrize("name", sorted(DETOURS))
def test_follower_reproduces_rmcs_waits_and_back_offs(tmp_path, name):
    base, scan, robots, steps, _, _ = DETOURS[name]
    trace = read_trace(DATA / f"{name}.rmc-trace.jsonl.gz")
    assert len(trace.steps) == steps
    assert max(r.failures for s in trace.states for r in s.robots.values()) >= 1  # backed off
    system, world = adapter.build(variant(tmp_path, base, scan, robots))
    result = follow(system, world, trace, violated=detour_progress)
    assert result.ok, str(result.divergence)
    assert result.steps == steps


@pytest.mark.parametrize("name", sorted(DETOURS))
def test_detour_counts_are_rmcs_in_rmcs_order(tmp_path, name):
    base, scan, robots, _, states, transitions = DETOURS[name]
    system, world = adapter.build(variant(tmp_path, base, scan, robots))
    counts = rmc_order.search(system, world, detour_progress)
    assert counts.violated
    assert (counts.states, counts.transitions) == (states, transitions)
