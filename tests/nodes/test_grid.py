from __future__ import annotations

import numpy as np
import pytest

from twinfleet.nodes.grid import (
    NB,
    Dims,
    cell_centre,
    cell_to_world,
    chebyshev,
    dir_to_heading,
    direction_between,
    heading_to_dir,
    in_bounds,
    inflate,
    inflate_one_pass,
    is_diagonal,
    octile,
    step,
    world_to_cell,
)


def test_nb_is_ccw_from_east():
    assert NB[0] == (1, 0)
    assert NB[2] == (0, 1)
    assert NB[4] == (-1, 0)
    assert NB[7] == (1, -1)


@pytest.mark.parametrize("d", range(8))
def test_direction_between_inverts_nb(d):
    assert direction_between((5, 5), step((5, 5), d, 3)) == d
    assert direction_between((5, 5), (5 + 7 * NB[d][0], 5 + 2 * NB[d][1])) == d


def test_direction_between_same_cell_raises():
    with pytest.raises(ValueError, match="itself"):
        direction_between((1, 1), (1, 1))


def test_octile_and_chebyshev():
    assert octile((0, 0), (3, 1)) == pytest.approx(0.4142 + 3)
    assert octile((2, 2), (2, 2)) == 0
    assert chebyshev((0, 0), (3, -5)) == 5


def test_is_diagonal():
    assert [is_diagonal(d) for d in range(8)] == [False, True] * 4


def test_cell_world_round_trip():
    assert cell_centre((0, 0), 0.255) == (0.1275, 0.1275)
    for cell in [(0, 0), (5, 7), (49, 3)]:
        x, y = cell_to_world(cell, 0.255, (-6.375, -6.375))
        assert world_to_cell(x, y, 0.255, (-6.375, -6.375)) == cell
    assert world_to_cell(-0.01, 0.0, 0.255) == (-1, 0)


def test_heading_dir():
    assert [dir_to_heading(d) for d in (0, 2, 7)] == [0.0, 90.0, 315.0]
    assert heading_to_dir(44.9) == 0
    assert heading_to_dir(45) == 1
    assert heading_to_dir(-1) == 7
    assert heading_to_dir(44.9, nearest=True) == 1
    assert heading_to_dir(350, nearest=True) == 0


def test_in_bounds():
    assert in_bounds((0, 0), (2, 3))
    assert in_bounds((1, 2), (2, 3))
    assert not in_bounds((2, 0), (2, 3))
    assert not in_bounds((0, -1), (2, 3))


def _inflate_brute(occ):
    rows, cols = occ.shape
    out = occ.copy()
    for x in range(rows):
        for y in range(cols):
            if occ[x, y]:
                for dx, dy in NB:
                    if 0 <= x + dx < rows and 0 <= y + dy < cols:
                        out[x + dx, y + dy] = True
    return out


def test_inflate_matches_brute_force():
    rng = np.random.default_rng(1)
    for _ in range(30):
        occ = rng.random((int(rng.integers(1, 12)), int(rng.integers(1, 12)))) < 0.1
        assert (inflate(occ) == _inflate_brute(occ)).all()
        assert (inflate(occ, 2) == _inflate_brute(_inflate_brute(occ))).all()
    assert (inflate(occ, 0) == occ).all()


def test_inflate_does_not_wrap():
    occ = np.zeros((3, 4), dtype=bool)
    occ[0, 3] = True
    out = inflate(occ)
    assert not out[1, 0]
    assert not out[0, 0]
    assert out[1, 2]


def test_inflate_map50_model_count(occ50):
    assert occ50.sum() == 213
    assert inflate(occ50).sum() > 213


def test_dims():
    d = Dims()
    assert d.steplen(0) == 0.255
    assert d.steplen(1) == pytest.approx(0.360621)
    with pytest.raises(ValueError, match="res"):
        Dims(res=0)


def _expand_in_place_like_the_model(occ):
    # expandObstacles of the model, statement by statement: each cell is copied into the
    # output when the row-major scan reaches it, then its obstacle marks its free neighbours.
    rows, cols = occ.shape
    out = np.zeros_like(occ)
    for x in range(rows):
        for y in range(cols):
            out[x, y] = occ[x, y]
            if occ[x, y]:
                for dx, dy in NB:
                    nx, ny = x + dx, y + dy
                    if 0 <= nx < rows and 0 <= ny < cols and not occ[nx, ny]:
                        out[nx, ny] = True
    return out


def test_one_pass_inflation_is_the_models_in_place_expansion():
    rng = np.random.default_rng(2)
    for _ in range(200):
        occ = rng.random((int(rng.integers(1, 10)), int(rng.integers(1, 10)))) < 0.2
        assert (inflate_one_pass(occ) == _expand_in_place_like_the_model(occ)).all()


def test_one_pass_inflation_grows_towards_lower_rows_and_columns_only():
    occ = np.zeros((5, 5), dtype=bool)
    occ[2, 2] = True
    out = inflate_one_pass(occ)
    assert sorted(zip(*np.nonzero(out), strict=True)) == [(1, 1), (1, 2), (1, 3), (2, 1), (2, 2)]


def test_one_pass_inflation_of_map50(occ50):
    assert inflate_one_pass(occ50).sum() == 315  # full dilation: 357
    assert inflate(occ50).sum() == 357
