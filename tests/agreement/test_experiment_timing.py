"""Checker arrival predictions, live run records, and the early-stop report."""

from __future__ import annotations

from pathlib import Path

from twinfleet.nodes.msgs import Collision, RobotStatus
from twinfleet.robots.live import LiveRunResult, TimedReport
from twinfleet.robots.timing import arrival_errors, predicted_arrivals, summarise

ROOT = Path(__file__).resolve().parents[2]


def _status(robot: str, mode: str, t: int) -> RobotStatus:
    return RobotStatus(robot, mode, (0, 0), (1, 1), 0, 0, t)


def test_c1a_arrivals_are_the_same_on_every_checker_path():
    walks = [predicted_arrivals(ROOT / "twinfleet" / "launch" / "c1a.yaml", seed=s) for s in range(3)]
    first = walks[0].arrival_ms
    assert set(first) == {"r1", "r2", "r3", "r4", "r5"}
    assert all(v is not None and v > 0 for v in first.values())
    assert all(w.arrival_ms == first for w in walks)


def test_a_walk_gives_up_at_the_horizon():
    p = predicted_arrivals(ROOT / "twinfleet" / "launch" / "c1a.yaml", horizon_ms=1000)
    assert all(v is None for v in p.arrival_ms.values())


def test_errors_are_per_robot_from_its_own_start():
    rec = LiveRunResult(seed=1, time_scale=5, reason="x", wall_s=1.0, failed_nodes=(),
                    arrived={"r1": True, "r2": False}, start_ms={"r1": 1000, "r2": 1010},
                    arrival_ms={"r1": 6100, "r2": None})
    assert rec.durations_ms == {"r1": 5100, "r2": None}
    assert rec.start_spread_ms == 10
    assert rec.verdict == "not arrived: r2" and not rec.passed
    errors = arrival_errors(rec.durations_ms, {"r1": 5000, "r2": 7000})
    assert errors == {"r1": 100}
    s = summarise([errors, {"r1": -50}], 2)
    assert (s.samples, s.mean_abs_ms, s.max_abs_ms, s.mean_signed_ms) == (2, 75.0, 100, 25.0)


def test_timed_report_decides_on_arrival_or_stuck():
    decided: list[str] = []
    report = TimedReport(("r1", "r2"), 0.255)
    report.on_decided = decided.append
    report.on_message("/r1/status", _status("r1", "planning", 500))
    report.on_message("/r1/status", _status("r1", "planning", 900))
    report.on_message("/r2/status", _status("r2", "planning", 520))
    report.on_message("/r1/status", _status("r1", "arrived", 4000))
    assert decided == [] and report.start_ms == {"r1": 500, "r2": 520}
    report.on_message("/r2/status", _status("r2", "stuck", 4100))
    assert decided == ["every robot arrived or is stuck (r2)"]
    report.on_message("/r2/status", _status("r2", "stuck", 4200))
    assert len(decided) == 1


def test_timed_report_stops_at_a_collision_only_when_asked():
    decided: list[str] = []
    report = TimedReport(("r1", "r2"), 0.255)
    report.on_decided = decided.append
    hit = Collision("r1", "r2", (3, 3), (3, 4), 2500)
    report.on_message("/collisions", hit)
    assert decided == [] and report.first_collision_ms == 2500
    report.stop_on_collision = True
    report.on_message("/collisions", hit)
    assert decided == ["collision r1-r2 at t=2500 ms"]


def test_private_copy_runs_the_same_scenario_from_elsewhere(tmp_path):
    from twinfleet.robots.live import private_copy
    from twinfleet.runtime.scenario.spec import load_scenario

    original = load_scenario(ROOT / "twinfleet" / "launch" / "c1a.yaml")
    copy = private_copy(original, tmp_path)
    assert copy.path == tmp_path / "c1a.yaml" and copy.path != original.path
    assert (copy.name, copy.fleet) == (original.name, original.fleet)
    assert [n.params for n in copy.nodes] == [n.params for n in original.nodes]
