"""Fixtures shared by the runtime and integration tests."""

from __future__ import annotations

import pytest

from tests.support import pick_free_port


@pytest.fixture
def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago."""
    return pick_free_port()
