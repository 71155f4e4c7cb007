"""The suite's xdist groups (tests/conftest.py): which group a test joins, and that a test
marked `offline` in a live folder names nothing that starts a fleet."""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import pytest

from tests.conftest import LIVE_FOLDERS, Group, _group
from tests.support import ROOT


@dataclass
class _Item:
    """What `_group` reads of a pytest item: its marks."""

    marks: frozenset[str] = field(default_factory=frozenset)

    def get_closest_marker(self, name: str) -> object | None:
        return name if name in self.marks else None


@pytest.mark.parametrize(("marks", "folder", "group"), [
    ((), "integration", Group.LIVE),
    (("fleet",), "", Group.LIVE),
    (("offline",), "integration", None),  # beside the live group
    (("ray",), "checker", Group.RAY),
    ((), "cluster", Group.RAY),
    (("install", "slow"), "", Group.INSTALL),
    ((), "checker", None),
])
def test_a_test_joins_the_group_of_its_folder_and_marks(marks, folder, group):
    assert _group(_Item(frozenset(marks)), folder) is group  # type: ignore[arg-type]


# What starts a fleet or opens a Zenoh session in a test file of a live folder.
FLEET_STARTERS = re.compile(r"launch_in\(|run_fleet\(|zenoh\.open\(|start_fleet\(|"
                            r"\"launch\", |Fleet\(")


def test_an_offline_test_file_names_nothing_that_starts_a_fleet():
    offline = [path for folder in LIVE_FOLDERS for path in (ROOT / "tests" / folder).glob("*.py")
               if "pytestmark = pytest.mark.offline" in path.read_text()]
    assert len(offline) >= 10
    for path in offline:
        found = FLEET_STARTERS.findall(path.read_text())
        assert not found, f"{path.relative_to(ROOT)} is offline but has {found}"
