"""A local cluster started beside the search runs at the lowest priority of its own
session's scheduling group (Linux's autogroup) until its workers take the search over
(`restore`), or a deadline."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any, cast

import pytest

from tests.integration.itest_support import poll
from twinfleet.checker.cluster import starting
from twinfleet.checker.cluster.head import BACKGROUND_NICENESS, Background

pytestmark = pytest.mark.timeout(60)
autogroups = pytest.mark.skipif(not Path("/proc/self/autogroup").exists(),
                                reason="the kernel has no autogroups (Linux only)")


def group(pid: int) -> str:
    """What the kernel says of `pid`'s autogroup: "/autogroup-N nice K", or nothing for a
    process in the kernel's default group (one whose session began before autogroups,
    as a CI runner's may)."""
    return Path(f"/proc/{pid}/autogroup").read_text()


def niceness(pid: int) -> int:
    """The niceness of `pid`'s autogroup (its session is its own, so it has one)."""
    return int(group(pid).split()[-1])


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


@autogroups
def test_lowered_until_restored(session: subprocess.Popen[bytes]) -> None:
    background = Background(session.pid)
    ours = group(os.getpid())
    background.lower(at_most_s=60)
    try:
        assert niceness(session.pid) == BACKGROUND_NICENESS
        assert group(os.getpid()) == ours  # the search's own group keeps its priority
    finally:
        background.restore()
    assert niceness(session.pid) == 0


@autogroups
def test_restored_at_the_deadline(session: subprocess.Popen[bytes]) -> None:
    background = Background(session.pid)
    background.lower(at_most_s=0.5)
    try:
        assert poll(lambda: niceness(session.pid) == 0, timeout=10, interval=0.05)
    finally:
        background.cancel()


@autogroups
def test_a_session_that_ended_is_no_error(session: subprocess.Popen[bytes]) -> None:
    background = Background(session.pid)
    session.kill()
    session.wait()
    background.lower(at_most_s=60)
    background.restore()  # nothing left to set: no error


class _Head:
    """A local cluster that is up at once, its priority recorded."""

    address = "127.0.0.1:1"
    driver_log = os.devnull

    def __init__(self) -> None:
        self.restored = 0
        self.background = self

    def wait_up(self) -> None:
        return None

    def restore(self) -> None:
        self.restored += 1


class _Engine:
    """`checker.cluster.engine` without Ray: joining and leaving do nothing."""

    @staticmethod
    def connect(address: str, log: str, local: bool) -> None:
        return None

    @staticmethod
    def disconnect() -> None:
        return None


class _Built:
    """A backend whose workers come up when the test says so."""

    def __init__(self) -> None:
        self.up = False

    def ready(self) -> bool:
        return self.up

    def close(self) -> None:
        return None


def test_restored_when_the_workers_take_over(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(starting, "_imported", lambda: _Engine)
    monkeypatch.setattr(starting, "prepare_environment", lambda local: None)  # Ray's, not ours
    head, built = _Head(), _Built()
    started = starting.Starting(2, lambda engine: built, cast(Any, head), None)
    try:
        assert poll(lambda: not started._thread.is_alive(), timeout=30)
        assert not started.ready()
        assert head.restored == 0  # still beside the search: still in the background
        built.up = True
        assert started.ready()
        assert head.restored == 1
    finally:
        started.close()
