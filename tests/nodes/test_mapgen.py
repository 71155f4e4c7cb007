from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from twinfleet.nodes.grid import inflate
from twinfleet.nodes.mapfile import load_map
from twinfleet.nodes.mapgen import corridor_map, lane_row, lanes_map, random_map, write_builtin_maps
from twinfleet.nodes.planning import generate_path
from twinfleet.nodes.profile import FIXED, REBECA

MAPS = Path(__file__).resolve().parents[2] / "twinfleet" / "maps"


def test_random_map_deterministic_and_free_border():
    a = random_map(40, 30, seed=5)
    assert (a == random_map(40, 30, seed=5)).all()
    assert not (a == random_map(40, 30, seed=6)).all()
    assert a.dtype == np.uint8
    assert set(np.unique(a)) <= {0, 255}
    assert (a[:3] == 255).all()
    assert (a[-3:] == 255).all()
    assert (a[:, :3] == 255).all()
    assert (a[:, -3:] == 255).all()
    assert (a == 0).any()


def test_random_map_too_small():
    with pytest.raises(ValueError, match="too small"):
        random_map(5, 5, seed=1)


def test_builtin_maps_regenerate_byte_identical(tmp_path):
    for y in write_builtin_maps(tmp_path):
        for suffix in (".yaml", ".pgm"):
            new = y.with_suffix(suffix)
            assert new.read_bytes() == (MAPS / new.name).read_bytes(), new.name


def test_corridor_two_lanes_and_passable():
    m = load_map(MAPS / "corridor12.yaml")
    assert (m.gray == corridor_map()).all()
    for p in (REBECA, FIXED):
        inf = inflate(m.occupied(p))
        assert not inf[5, 3:9].any()
        assert not inf[6, 3:9].any()
        assert inf[4, 3:9].all()
        assert inf[7, 3:9].all()
        assert generate_path(inf, (5, 0), (6, 11), p) is not None


def test_random100_loads_and_connects():
    m = load_map(MAPS / "random100.yaml")
    assert m.shape == (100, 100)
    inf = inflate(m.occupied(FIXED))
    assert generate_path(inf, (1, 1), (98, 98), FIXED) is not None


def test_lanes_are_walled_off_from_each_other():
    img = lanes_map(3, 20)
    assert img.shape == (13, 20)
    occ = img == 0
    for k in range(3):
        row = lane_row(k)
        assert not occ[row - 1 : row + 2, 1:19].any()  # the lane's three free rows
        assert occ[row - 2].all() and occ[row + 2].all()  # walls on both sides
    assert occ[:, 0].all() and occ[:, -1].all()  # closed ends: lanes never meet


@pytest.mark.parametrize("profile", [FIXED, REBECA])
def test_each_lane_is_plannable_only_within_itself(profile):
    lanes = 4
    occ = lanes_map(lanes, 16) == 0
    inf = inflate(occ)
    for k in range(lanes):
        row = lane_row(k)
        assert not inf[row, 2:14].any()  # one planning row survives the inflation
        path = generate_path(inf, (row, 2), (row, 13), profile)
        assert path is not None and {c[0] for c in path} == {row}
        if k:
            assert generate_path(inf, (row, 2), (lane_row(k - 1), 13), profile) is None


def test_lanes_map_rejects_degenerate_sizes():
    with pytest.raises(ValueError, match="lanes >= 1"):
        lanes_map(0, 10)
    with pytest.raises(ValueError, match="length >= 5"):
        lanes_map(2, 4)
