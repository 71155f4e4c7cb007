"""The robots are an example on the public API: the framework names none of their concepts.

Checked on the source, grep-style (docs/design.md §1, docs/robots.md §9):

- the generic scenario format (`runtime/scenario/`) has no `map` or `profile` key: they
  are the robot nodes' own parameters;
- no robot type (node, parameter, message, scene or report class of the robots) is named
  outside the robots' packages, `twinfleet/nodes/` (their node code) and
  `twinfleet/robots/` (their experiment);
- the command line (`twinfleet/cli/`) imports the robots' packages only where the
  application is wired (`cli/main.py` registers their examples, renderer and command):
  every other command reaches them through what was registered;
- no code reads a reason as English (`reason.startswith(`): what ended a run is an
  `EndReason`, why a call failed a `CallFailure`.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

pytestmark = pytest.mark.timeout(60)

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "twinfleet"
ROBOT_PACKAGES = (PACKAGE / "nodes", PACKAGE / "robots")
#: the robots' own types, each defined in a module of `ROBOT_PACKAGES`
ROBOT_TYPES = ("Robot", "RobotParams", "RobotState", "MapServer", "MapServerParams",
               "RobotStatus", "RobotPose", "ObstacleScan", "FleetStatus", "PathRequest",
               "RobotScene", "FleetReport", "TimedReport", "PaperRow")
SCENARIO_KEYS = ("map", "profile")


def _sources(folder: Path) -> list[Path]:
    return sorted(folder.rglob("*.py"))


def _outside_the_robots() -> list[Path]:
    return [p for p in _sources(PACKAGE) if not any(p.is_relative_to(r) for r in ROBOT_PACKAGES)]


def test_every_robot_type_named_here_is_defined_by_the_robots():
    defined = {node.name for folder in ROBOT_PACKAGES for path in _sources(folder)
               for node in ast.walk(ast.parse(path.read_text())) if isinstance(node, ast.ClassDef)}
    assert set(ROBOT_TYPES) <= defined


def test_no_robot_type_is_named_outside_the_robots_packages():
    word = re.compile(r"\b(" + "|".join(ROBOT_TYPES) + r")\b")
    found = [f"{path.relative_to(ROOT)}:{n}: {match.group()}"
             for path in _outside_the_robots()
             for n, line in enumerate(path.read_text().splitlines(), 1)
             for match in word.finditer(line)]
    assert found == []


def test_the_scenario_format_has_no_robot_keys():
    """No string constant `"map"`/`"profile"` and no `map:`/`profile:` key line anywhere in
    `runtime/scenario/` (code, docstrings or comments)."""
    found = []
    for path in _sources(PACKAGE / "runtime" / "scenario"):
        text = path.read_text()
        found += [f"{path.name}: constant {node.value!r}" for node in ast.walk(ast.parse(text))
                  if isinstance(node, ast.Constant) and node.value in SCENARIO_KEYS]
        found += [f"{path.name}:{n}: {line.strip()}" for n, line in enumerate(text.splitlines(), 1)
                  if re.search(r"\b(map|profile)\s*:", line) or re.search(r"\bPROFILES?\b", line)]
    assert found == []


def test_the_scenario_checks_see_a_key_line(tmp_path):
    """The pattern above finds the old top-level keys as they were written."""
    old = "name: c1a\nmap: ../maps/map50.yaml\nprofile: fixed\n"
    assert [line for line in old.splitlines() if re.search(r"\b(map|profile)\s*:", line)] == [
        "map: ../maps/map50.yaml", "profile: fixed"]



#: where the command line is wired to the robots (their examples, renderer and command)
WIRING = PACKAGE / "cli" / "main.py"


def _imports(path: Path) -> list[str]:
    """The modules `path` imports by a statement, at any depth (a function's lazy imports too)."""
    found: list[str] = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.append(node.module)
    return found


def test_the_command_line_imports_the_robots_only_where_it_is_wired():
    robots = tuple(f"twinfleet.{p.name}" for p in ROBOT_PACKAGES)
    found = [f"{path.relative_to(ROOT)}: {name}" for path in _sources(PACKAGE / "cli")
             if path != WIRING for name in _imports(path)
             if name == "twinfleet" or name.startswith(tuple(f"{r}" for r in robots))]
    assert found == []
    assert any(name.startswith(robots) for name in _imports(WIRING))  # the check sees imports


def test_no_reason_is_parsed_as_english():
    found = [f"{path.relative_to(ROOT)}:{n}" for path in _sources(PACKAGE)
             for n, line in enumerate(path.read_text().splitlines(), 1)
             if "reason.startswith(" in line]
    assert found == []
