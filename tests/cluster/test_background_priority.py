"""A local cluster started beside the search runs at the lowest priority of its own
session's scheduling group (Linux's autogroup) until `restore`, or a deadline."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.integration.itest_support import poll
from twinfleet.checker.cluster.head import BACKGROUND_NICENESS, Background

pytestmark = [pytest.mark.timeout(60),
              pytest.mark.skipif(not Path("/proc/self/autogroup").exists(),
                                 reason="the kernel has no autogroups (Linux only)")]


def niceness(pid: int) -> int:
    """The niceness of `pid`'s autogroup ("/autogroup-N nice K")."""
    return int(Path(f"/proc/{pid}/autogroup").read_text().split()[-1])


@pytest.fixture
def session() -> Iterator[subprocess.Popen[bytes]]:
    """A process leading a session of its own, as `ray start` does for a cluster."""
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"],
                            start_new_session=True)
    try:
        yield proc
    finally:
        proc.kill()
        proc.wait()


def test_lowered_until_restored(session: subprocess.Popen[bytes]) -> None:
    background = Background(session.pid)
    before = niceness(session.pid)
    background.lower(at_most_s=60)
    try:
        assert niceness(session.pid) == BACKGROUND_NICENESS
        assert niceness(os.getpid()) == before  # the search's own group keeps its priority
    finally:
        background.restore()
    assert niceness(session.pid) == 0


def test_restored_at_the_deadline(session: subprocess.Popen[bytes]) -> None:
    background = Background(session.pid)
    background.lower(at_most_s=0.5)
    try:
        assert poll(lambda: niceness(session.pid) == 0, timeout=10, interval=0.05)
    finally:
        background.cancel()


def test_a_session_that_ended_is_no_error(session: subprocess.Popen[bytes]) -> None:
    background = Background(session.pid)
    session.kill()
    session.wait()
    background.lower(at_most_s=60)
    background.restore()  # nothing left to set: no error
