from __future__ import annotations

import pytest

from twinfleet.nodes.motion import (
    cells_per_second,
    check_cell_size_rule,
    check_scan_rate_rule,
    distance_to_target,
    hop_time_ms,
    max_waiting_rounds,
    rotation_time_ms,
    within_tolerance,
)
from twinfleet.nodes.profile import FIXED, REBECA

SPEEDS = (0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0)


def test_hop_times_model_table():
    assert [hop_time_ms(v, False, 0.255, REBECA) for v in SPEEDS] == [
        851, 638, 511, 426, 365, 319, 284, 256,
    ]
    assert [hop_time_ms(v, True, 0.255, REBECA) for v in SPEEDS] == [
        1203, 902, 722, 602, 516, 451, 401, 361,
    ]


def test_hop_times_fixed():
    assert hop_time_ms(0.3, False, 0.255, FIXED) == 850
    assert hop_time_ms(1.0, False, 0.255, FIXED) == 255
    with pytest.raises(ValueError, match="positive"):
        hop_time_ms(0.0, False, 0.255, FIXED)


def test_default_velocity_table():
    assert [cells_per_second(v, 0.255, REBECA) for v in SPEEDS] == [2, 2, 2, 3, 3, 4, 4, 4]


def test_rotation_times():
    assert [rotation_time_ms(0, k, REBECA) for k in range(1, 8)] == [
        126, 251, 376, 501, 626, 751, 876,
    ]
    assert rotation_time_ms(7, 0, REBECA) == 876  # no wrap-around
    assert rotation_time_ms(7, 0, FIXED) == 125
    assert rotation_time_ms(0, 4, FIXED) == 500
    assert rotation_time_ms(3, 3, REBECA) == 0


@pytest.mark.parametrize(
    ("rate", "waits", "want_model", "want_fixed"),
    [
        (100, (1500, 2000, 2500, 3000), [16, 21, 26, 31], [15, 20, 25, 30]),
        (140, (1500, 2000, 2500, 3000), [11, 15, 18, 22], [11, 14, 18, 21]),
    ],
)
def test_max_waiting_rounds(rate, waits, want_model, want_fixed):
    assert [max_waiting_rounds(w, rate, REBECA) for w in waits] == want_model
    assert [max_waiting_rounds(w, rate, FIXED) for w in waits] == want_fixed


def test_distance_and_tolerance():
    assert distance_to_target((5, 5), (5, 5), REBECA) == 0
    assert distance_to_target((5, 5), (6, 6), REBECA) == 2
    assert distance_to_target((5, 5), (6, 5), REBECA) == 2
    assert distance_to_target((5, 5), (7, 5), REBECA) == 3
    for dx in range(-3, 4):
        for dy in range(-3, 4):
            inside = within_tolerance((5, 5), (5 + dx, 5 + dy), 2, REBECA)
            assert inside == (max(abs(dx), abs(dy)) <= 1)


def test_scan_rate_rule():
    # C2c's r5 (1.0 m/s, 256 ms < 280 ms) breaks Eq. 1; C2a's 0.9 m/s (284 ms) satisfies it.
    assert check_scan_rate_rule(0.9, 0.255, 140, REBECA) is None
    msg = check_scan_rate_rule(1.0, 0.255, 140, REBECA)
    assert msg is not None
    assert "256" in msg
    assert "0.9107" in msg
    assert check_scan_rate_rule(0.5, 0.255, 100, FIXED) is None


def test_cell_size_rule():
    assert check_cell_size_rule(0.255, 0.4) is None
    assert "Eq. 2" in check_cell_size_rule(0.3, 0.4)
