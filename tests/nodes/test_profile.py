from __future__ import annotations

import pytest

from twinfleet.nodes.profile import FIXED, REBECA, profile_named, round_half_away, round_m


@pytest.mark.parametrize(
    ("x", "want"), [(0, 0), (0.4, 1), (1.96, 2), (2.0, 3), (15.0, 16), (-1.1, -2), (-2.0, -3)]
)
def test_round_m_examples(x, want):
    assert round_m(x) == want
    assert REBECA.round(x) == want


@pytest.mark.parametrize(("x", "want"), [(0, 0), (0.5, 1), (1.5, 2), (2.5, 3), (-0.5, -1), (2.4, 2)])
def test_round_half_away(x, want):
    assert round_half_away(x) == want
    assert FIXED.round(x) == want


def test_profile_named():
    assert profile_named("fixed") is FIXED
    assert profile_named("rebeca") is REBECA
    with pytest.raises(ValueError, match="fixed, rebeca"):
        profile_named("ros")


def test_profiles_are_frozen():
    with pytest.raises(AttributeError):
        FIXED.round_model = True  # type: ignore[misc]
