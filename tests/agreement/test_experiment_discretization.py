"""Resampled maps and scenarios, and the paper's discretization rules."""

from __future__ import annotations

import math
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from twinfleet.nodes.mapfile import load_map
from twinfleet.nodes.profile import FIXED
from twinfleet.robots.discretization import (
    cell_rules,
    hidden_overlap_m,
    scale_map,
    scale_scenario,
)
from twinfleet.runtime.scenario.spec import load_scenario

pytestmark = pytest.mark.offline  # starts no fleet, opens no Zenoh session

ROOT = Path(__file__).resolve().parents[2]
MAP50 = ROOT / "twinfleet" / "maps" / "map50.yaml"


def test_refining_by_two_keeps_the_obstacles_and_halves_the_cell(tmp_path):
    fine = load_map(scale_map(MAP50, Fraction(2), tmp_path / "fine.yaml"))
    src = load_map(MAP50)
    assert fine.shape == (100, 100)
    assert fine.resolution == pytest.approx(0.1275)
    occ, occ_fine = src.occupied(FIXED), fine.occupied(FIXED)
    assert np.array_equal(occ_fine, np.repeat(np.repeat(occ, 2, 0), 2, 1))


def test_coarsening_marks_a_block_occupied_if_any_cell_was(tmp_path):
    coarse = load_map(scale_map(MAP50, Fraction(1, 2), tmp_path / "coarse.yaml"))
    occ = load_map(MAP50).occupied(FIXED)
    assert coarse.shape == (25, 25) and coarse.resolution == pytest.approx(0.51)
    expected = occ.reshape(25, 2, 25, 2).any(axis=(1, 3))
    assert np.array_equal(coarse.occupied(FIXED), expected)


def test_scaled_scenario_loads_with_scaled_cells_and_rules(tmp_path):
    fine_map = scale_map(MAP50, Fraction(2), tmp_path / "maps" / "fine.yaml")
    out = scale_scenario(ROOT / "twinfleet" / "launch" / "c1a.yaml", Fraction(2), fine_map,
                         tmp_path / "c1a_fine.yaml", name="c1a_fine")
    sc = load_scenario(out)
    assert sc.name == "c1a_fine" and sc.node("r1").params.map == str(fine_map.resolve())
    r1 = sc.node("r1").params
    assert (r1.start, r1.goal) == ((10, 10), (90, 90))
    rules = cell_rules(out)
    assert rules.cell_rule is None  # 0.1275 < 0.2828
    # hop 0.1275 m: 0.7 and 0.8 m/s need 182 and 159 ms, not above 2 x 100 ms (Eq. 1)
    assert rules.unsafe_robots == ("r2", "r3")
    assert sc.node("r2").params.allow_unsafe_speed and not r1.allow_unsafe_speed
    halved = scale_scenario(ROOT / "twinfleet" / "launch" / "c1a.yaml", Fraction(2), fine_map,
                            tmp_path / "c1a_fine50.yaml", scan_rate_ms=50)
    assert cell_rules(halved).unsafe_robots == ()


@pytest.mark.filterwarnings("ignore:.*breaks Eq. 2")
def test_the_paper_map_keeps_eq2_and_a_coarse_one_breaks_it(tmp_path):
    assert cell_rules(ROOT / "twinfleet" / "launch" / "c1a.yaml").cell_rule is None
    coarse = scale_map(MAP50, Fraction(1, 2), tmp_path / "coarse.yaml")
    out = scale_scenario(ROOT / "twinfleet" / "launch" / "c1a.yaml", Fraction(1, 2), coarse,
                         tmp_path / "c1a_coarse.yaml")
    rules = cell_rules(out)
    assert rules.cell_rule is not None and "0.2828" in rules.cell_rule
    assert rules.bound_m == pytest.approx(0.4 / math.sqrt(2))


def test_hidden_overlap():
    # A diagonal hop exactly as long as the robot hides L(1 - sqrt(3)/2).
    assert hidden_overlap_m(0.4, 0.4) == pytest.approx(0.4 * (1 - math.sqrt(3) / 2))
    assert hidden_overlap_m(0.255 * math.sqrt(2), 0.4) == pytest.approx(0.0429, abs=1e-4)
    assert hidden_overlap_m(0.0, 0.4) == 0.0
    assert hidden_overlap_m(0.9, 0.4) == 0.4  # jumps clean through
