"""Fixtures shared by the runtime and integration tests."""

from __future__ import annotations

import ctypes
import enum
import os
import signal
import sys
import tempfile

import pytest

# Under pytest-xdist each worker gets its own temporary directory (before anything below
# creates one): tests that look for files a run leaves in the temporary directory, and the
# processes they start, then never see another worker's.
if os.environ.get("PYTEST_XDIST_WORKER"):
    os.environ["TMPDIR"] = tempfile.mkdtemp(prefix=f"tf-{os.environ['PYTEST_XDIST_WORKER']}-")
    tempfile.tempdir = None

from tests.support import RUNTIME_DIR, pick_free_port  # noqa: E402
from twinfleet.robots import EXAMPLES  # noqa: E402
from twinfleet.runtime.scenario.examples import add_examples  # noqa: E402

# A test ends only the processes it started (tests/integration/itest_support.py `spawned_by`).
# A node whose launcher was killed would be adopted by init and lost from view; as the
# subreaper of everything it starts, this test process adopts such orphans itself instead.
PR_SET_CHILD_SUBREAPER = 36
if sys.platform == "linux":
    ctypes.CDLL(None, use_errno=True).prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0)

# Tests press Ctrl-C (send SIGINT) to the commands they start. A test run started in the
# background by a non-interactive shell (`cmd &`) ignores SIGINT, an ignored signal stays
# ignored across exec, and a command that finds SIGINT ignored at its start keeps ignoring it,
# as POSIX asks: those tests would then wait for a command that never hears them.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

# Commands run in-process (`twinfleet.cli.main([...])`) read the fleet registry too: give them
# the test session's private one, as `child_env` gives it to subprocesses, so that a fleet the
# developer (or another test session on this machine) runs is never found by a test.
os.environ["XDG_RUNTIME_DIR"] = RUNTIME_DIR
os.environ.pop("TWINFLEET_RUNTIME_DIR", None)

# Tests load the shipped examples by name, as the command line does (which adds them).
add_examples(EXAMPLES)


@pytest.fixture
def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago."""
    return pick_free_port()


# Tests that run fleets of real processes (these folders, and tests marked `fleet`) are
# timed against the wall clock: under pytest-xdist they share one group, so two fleets never
# compete for this machine's cores, while the CPU-bound checker tests run beside them on the
# other worker. A slow test that starts no fleet is not in it: the group is the suite's
# longest chain of tests.
LIVE_FOLDERS = frozenset({"adversarial", "agreement", "conformance", "integration", "ros2",
                          "viewer"})
# A test of a live folder that starts no fleet and times nothing (marked `offline`: the pure
# parts of the agreement, viewer and ROS 2 code, commands that refuse bad input or print
# help) runs beside the live group, not in it; like a unit test it may not open a Zenoh
# session.
# The Ray tests (this folder, and tests marked `ray`) start clusters, not fleets: CPU-bound
# like the checker tests, they form a group of their own (one Ray cluster at a time).
RAY_FOLDERS = frozenset({"cluster"})


# The install tests (marked `install`: tests/test_wheel.py) build three virtual environments
# with pip, CPU-bound like the checker tests, and judge their two short fleets by the nodes'
# exit codes and by a verdict that needs no timing (every node started and heard the
# other): a group of their own (the environments are built once per worker), beside the
# live group instead of a fifth of its length.
class Group(enum.Enum):
    """The xdist groups, longest first: the suite starts them first, so that none of them
    starts last and runs on alone while the other worker idles."""

    LIVE = "live"
    RAY = "ray"
    INSTALL = "install"


def _group(item: pytest.Item, folder: str) -> Group | None:
    if item.get_closest_marker("ray") or folder in RAY_FOLDERS:
        return Group.RAY
    if item.get_closest_marker("install"):
        return Group.INSTALL
    if item.get_closest_marker("offline"):
        return None
    if item.get_closest_marker("fleet") or folder in LIVE_FOLDERS:
        return Group.LIVE
    return None


# tryfirst: pytest-xdist reads the xdist_group marks in its own collection hook (it turns
# them into the `@live` suffix its scheduler groups by); a mark added after it has no effect.
@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Put every live test into the `live` xdist group, the Ray tests into `ray`, the install
    tests into `install` (no effect without xdist), and the groups' tests first."""
    tests_root = config.rootpath / "tests"
    order = list(Group)
    rank: dict[str, int] = {}
    for item in items:
        parts = item.path.relative_to(tests_root).parts
        folder = parts[0] if len(parts) > 1 else ""
        group = _group(item, folder)
        if group is not None:
            item.add_marker(pytest.mark.xdist_group(group.value))
        elif folder in UNIT_FOLDERS and not item.get_closest_marker("slow"):
            item.add_marker(pytest.mark.unit)
        rank[item.nodeid] = order.index(group) if group is not None else len(order)
    items.sort(key=lambda item: rank[item.nodeid])  # stable: a module's tests stay together


# The quick loop (`pytest -m unit`, under a minute on 2 cores): the tests of these folders
# that are neither slow nor live nor Ray tests. A unit test opens no Zenoh session (the
# fixture below refuses it): one that needs Zenoh is a `fleet` test.
UNIT_FOLDERS = frozenset({"", "checker", "nodes", "runtime", "sweep", "fuzz", "interfaces"})


@pytest.fixture(autouse=True)
def _unit_tests_open_no_zenoh_session(request: pytest.FixtureRequest,
                                      monkeypatch: pytest.MonkeyPatch) -> None:
    if request.node.get_closest_marker("unit") is None and \
            request.node.get_closest_marker("offline") is None:
        return
    import zenoh

    def refuse(*_args: object, **_kwargs: object) -> None:
        raise AssertionError(f"{request.node.nodeid} is a unit or offline test but opens a Zenoh"
                             " session: mark it `fleet` (tests/conftest.py)")

    monkeypatch.setattr(zenoh, "open", refuse)
