"""Fixtures shared by the runtime and integration tests."""

from __future__ import annotations

import os

import pytest

from tests.support import RUNTIME_DIR, pick_free_port

# Commands run in-process (`twinfleet.cli.main([...])`) read the fleet registry too: give them
# the test session's private one, as `child_env` gives it to subprocesses, so that a fleet the
# developer (or another test session on this machine) runs is never found by a test.
os.environ["XDG_RUNTIME_DIR"] = RUNTIME_DIR
os.environ.pop("TWINFLEET_RUNTIME_DIR", None)


@pytest.fixture
def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago."""
    return pick_free_port()
