"""The checker on the robot system: the paper's cases, counts pinned (a changed number is a
review question, not noise)."""

from __future__ import annotations

from pathlib import Path

import pytest

from twinfleet.checker.check import CheckOptions, check, load
from twinfleet.checker.properties import PropertySet
from twinfleet.checker.system import System
from twinfleet.checker.trace import replay

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.timeout(300)


def run(name: str, **options):
    return check(ROOT / "launch" / f"{name}.yaml", CheckOptions(**options))


@pytest.mark.parametrize(
    ("name", "states", "rmc_transitions"),
    [
        ("c1a_rebeca", 19_559, 45_481),  # paper Table 4: 19,264 / 43,814
        ("c1b_rebeca", 20_127, 46_833),  # paper: 20,554 / 46,868
        ("c1c_rebeca", 15_263, 35_354),  # paper: 15,747 / 35,642
    ],
)
def test_working_cases_hold_in_the_paper_profile_and_semantics(name, states, rmc_transitions):
    result = run(name)
    assert result.status == "holds"
    assert result.statistics.states == states
    assert result.rmc_transitions == rmc_transitions


def test_c2c_collides_in_the_paper_profile_and_the_trace_replays(tmp_path):
    result = run("c2c_rebeca", trace_out=str(tmp_path / "c2c.json"))
    assert result.status == "violated"
    assert result.violation.property == "no_collision"
    assert result.statistics.states == 1_636  # paper Table 5: 1,740 when the collision was found
    scenario = load(result.trace["scenario"], profile=result.trace["profile"])
    system = System(scenario, semantics=result.trace["semantics"],
                    monitors=PropertySet.from_scenario(scenario))
    assert replay(system, result.trace).confirmed


@pytest.mark.parametrize("name", ["c2a", "c2b", "c2c"])
def test_non_working_cases_collide_in_the_fixed_profile(name):
    result = run(name, semantics="rebeca")
    assert result.status == "violated"
    assert result.violation.property == "no_collision"


def test_c1a_holds_in_the_fixed_profile_under_ros_semantics_including_arrival():
    result = run("c1a")
    assert result.status == "holds"
    assert "all_arrive" in " ".join(result.properties)
    assert result.statistics.states == 41_608
    assert result.statistics.transitions == 128_800


def test_headon_collides_and_the_shortest_trace_is_found():
    result = run("headon")
    assert result.status == "violated"
    assert result.violation.property == "no_collision"
    assert len(result.trace["steps"]) == 162


def test_paper_c2a_never_brings_two_robots_within_one_cell(capsys):
    # benchmarks/paper_c2_analysis.py: why C2a holds in the paper's profile (docs/results.md)
    import importlib.util

    path = Path(__file__).resolve().parents[1] / "benchmarks" / "paper_c2_analysis.py"
    spec = importlib.util.spec_from_file_location("paper_c2_analysis", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.main(["--cases", "c2a", "c2c", "--no-sweep"]) == 0
    rows = [line.split(" | ") for line in capsys.readouterr().out.splitlines() if " | " in line]
    assert rows[1][:4] == ["c2a", "holds", "5761", "2"]  # closest approach: two cells
    assert rows[2][:4] == ["c2c", "violated", "1636", "1"]
