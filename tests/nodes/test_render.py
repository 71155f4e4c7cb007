"""Pictures are checked by their pixels, not only by their existence."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from twinfleet.nodes.render import LEGEND_PX, draw_world, robot_colour, scenario_view, states_view
from twinfleet.runtime.scenario.spec import load_scenario

ROOT = Path(__file__).resolve().parents[2]
PX = 12


def pixel(img, cell):
    row, col = cell
    return tuple(np.asarray(img)[int((row + 0.5) * PX), int((col + 0.5) * PX) - 3])


def test_c1a_picture_shows_map_and_each_robot_in_its_colour_at_its_start():
    scenario = load_scenario(ROOT / "twinfleet" / "launch" / "c1a.yaml")
    img = draw_world(scenario_view(scenario), cell_px=PX)
    caption_px = 18 if scenario_view(scenario).caption else 0
    assert img.size == (50 * PX, 50 * PX + LEGEND_PX + caption_px)
    arr = np.asarray(img)
    assert tuple(arr[int(15.5 * PX), int(20.5 * PX)]) == (60, 60, 60)  # obstacle A
    for i, cfg in enumerate(c for c in scenario.nodes if c.name.startswith("r")):
        assert pixel(img, cfg.params.start) == robot_colour(i), cfg.name


def test_collision_is_circled_in_red(tmp_path):
    scenario = load_scenario(ROOT / "twinfleet" / "launch" / "c1a.yaml")
    r1, r2 = scenario.node("r1").instantiate(), scenario.node("r2").instantiate()
    r1.state.cell, r2.state.cell = (20, 30), (20, 31)
    view = states_view(scenario, {"r1": r1.state, "r2": r2.state}, collision=("r1", "r2"))
    img = draw_world(view, cell_px=PX)
    arr = np.asarray(img)
    red = np.all(arr == (255, 0, 0), axis=-1)
    assert red[int(18.5 * PX):int(22.5 * PX), int(28.5 * PX):int(33.5 * PX)].sum() > 40
    assert red.sum() < 2000  # only around the pair
    img.save(tmp_path / "collision.png")
