from __future__ import annotations

import numpy as np

from twinfleet.nodes.congestion import (
    BACKOFF_STEPS,
    BackoffOption,
    backoff_candidates,
    backoff_options,
    backoff_target,
    clamp_target,
    selection_sort_desc,
    target_margin,
    target_valid,
)
from twinfleet.nodes.grid import Dims, inflate
from twinfleet.nodes.profile import FIXED, REBECA
from twinfleet.nodes.scan import stepwise_free


def test_steps_constant():
    assert BACKOFF_STEPS == (4, 6, 8, 10, 12)


def test_selection_sort_is_the_models_unstable_sort():
    recs = [(0, 5), (1, 9), (2, 5), (3, 9), (4, 1), (5, 5), (6, 0), (7, 5)]
    out = selection_sort_desc(recs)
    assert [k for _, k in out] == sorted((k for _, k in recs), reverse=True)
    # p=0 swaps (1,9) with (0,5); p=1 takes (3,9) and swaps it with (0,5);
    # p=2: first max 5 among [(2,5),(0,5),(4,1),(5,5),(6,0),(7,5)] is (2,5) ...
    assert out[:4] == [(1, 9), (3, 9), (2, 5), (0, 5)]
    assert out == [(1, 9), (3, 9), (2, 5), (0, 5), (5, 5), (7, 5), (4, 1), (6, 0)]


def test_candidates_unseen_directions_count_999():
    assert backoff_candidates((10, 10), [], Dims(), REBECA) == ((0, 999), (1, 999), (2, 999), (3, 999))


def test_candidates_rank_by_free_space():
    # walls 3 cells east (x = 13) and 1 cell north (y = 11) of (10, 10)
    obs = [(13, y) for y in range(0, 12)] + [(x, 11) for x in range(0, 14)]
    cands = backoff_candidates((10, 10), obs, Dims(), REBECA)
    assert [d for d, _ in cands] == [4, 5, 6, 0]
    assert [m for _, m in cands][:3] == [999, 999, 999]
    assert cands[3][1] == stepwise_free((10, 10), 0, obs, 0.255, 0.4, 0.02)
    assert cands[3][1] in (1, 2)


def test_candidates_match_stepwise_counts_and_sort():
    rng = np.random.default_rng(4)
    for _ in range(50):
        obs = [tuple(int(v) for v in rng.integers(0, 30, 2)) for _ in range(12)]
        cands = backoff_candidates((15, 15), obs, Dims(), REBECA)
        recs = []
        for d in range(8):
            f = stepwise_free((15, 15), d, obs, 0.255, 0.4, 0.02)
            recs.append((d, 999 if f == 9999 else f))
        assert cands == tuple(selection_sort_desc(recs)[:4])
        assert [m for _, m in cands] == sorted((m for _, m in recs), reverse=True)[:4]


def test_backoff_target_and_clamp():
    assert backoff_target((10, 10), 4, 6, 999, 50, 50) == (4, 10)
    assert backoff_target((10, 10), 4, 12, 3, 50, 50) == (7, 10)
    assert backoff_target((3, 3), 5, 12, 999, 50, 50) == (1, 1)
    assert backoff_target((10, 10), 0, 4, 0, 50, 50) == (10, 10)
    assert clamp_target((60, -5), 50, 50) == (48, 1)
    assert target_margin(Dims(), REBECA) == 1
    assert target_margin(Dims(), FIXED) == 0


def test_options_rebeca_all_twenty():
    occ = np.zeros((50, 50), dtype=bool)
    cands = ((4, 999), (5, 3), (6, 0), (7, 999))
    opts = backoff_options((10, 10), cands, inflate(occ), Dims(), REBECA)
    assert len(opts) == 20
    assert opts[0] == BackoffOption(4, 4, (6, 10))
    assert opts[5] == BackoffOption(5, 3, (7, 7))
    assert opts[9] == BackoffOption(5, 3, (7, 7))
    assert opts[10].target == (10, 10)  # zero steps: the model plans to its own cell


def test_options_fixed_validated():
    occ = np.zeros((50, 50), dtype=bool)
    occ[4:6, 8:12] = True
    inf = inflate(occ)
    cands = ((4, 999), (5, 3), (6, 0), (7, 999))
    opts = backoff_options((10, 10), cands, inf, Dims(), FIXED)
    targets = [o.target for o in opts]
    assert len(targets) == len(set(targets))
    assert (10, 10) not in targets  # zero-step dropped
    assert (6, 10) not in targets
    assert (7, 7) in targets  # SW capped at maxback 3
    for o in opts:
        assert not inf[o.target]
    # W by 12 from (10, 10) leaves the map: dropped (the model would clamp it)
    assert all(not (o.dir == 4 and o.steps == 12) for o in opts)
    assert target_valid((10, 10), (20, 10), (20, 10), inf)
    assert not target_valid((10, 10), (0, 10), (-2, 10), inf)
