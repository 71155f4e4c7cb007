"""Shared fixtures for the domain-code tests."""

from __future__ import annotations

from pathlib import Path

import pytest

from twinfleet.nodes.grid import inflate_one_pass
from twinfleet.nodes.mapfile import OccupancyMap, load_map
from twinfleet.nodes.profile import REBECA

MAPS = Path(__file__).resolve().parents[2] / "twinfleet" / "maps"


@pytest.fixture(scope="session")
def map50() -> OccupancyMap:
    return load_map(MAPS / "map50.yaml")


@pytest.fixture(scope="session")
def occ50(map50):
    return map50.occupied(REBECA)


@pytest.fixture(scope="session")
def inflated50(occ50):
    """The model's planning inflation of the paper's map (what the `rebeca` map server uses)."""
    return inflate_one_pass(occ50)
