"""Source rules that imports do not show.

- The framework does not know the case study by name (below).
- The fleet reads node statistics by field, never `stats.get(`.
- Production never reads its own source (`inspect.getsource(` only under tests/).
- Key expressions are built only in `runtime/host/keys.py` (tests/runtime/test_keys.py).

`twinfleet/runtime/` draws, records and lists any fleet; what the robot case
study publishes is known to `twinfleet/nodes/` (its scene,
`twinfleet/nodes/scene.py`) and named by its scenarios. So no file under
`twinfleet/runtime/`, the viewer's page and script included, may spell the
package of the case study's message types (``twinfleet_msgs/``, read from
`twinfleet.nodes.msgs` so that a renamed package is still caught).
"""

from __future__ import annotations

from pathlib import Path

import pytest

import twinfleet.nodes.msgs as case_study_msgs

pytestmark = pytest.mark.timeout(60)

ROOT = Path(__file__).resolve().parents[1]
RUNTIME = ROOT / "twinfleet" / "runtime"


def _case_study_packages() -> set[str]:
    """``<package>/`` of every message type the case study defines."""
    names = [getattr(v, "__message_type__", None) for v in vars(case_study_msgs).values()]
    return {n.split("/")[0] + "/" for n in names if isinstance(n, str)}


def _runtime_files() -> list[Path]:
    return sorted(p for p in RUNTIME.rglob("*")
                  if p.is_file() and "__pycache__" not in p.parts)


def test_the_rule_reads_every_kind_of_runtime_file():
    names = {p.relative_to(RUNTIME).as_posix() for p in _runtime_files()}
    assert {"tools/view/static/viewer.js", "tools/view/static/index.html",
            "tools/view/viewstate.py"} <= names
    assert _case_study_packages() == {"twinfleet_msgs/"}


def test_the_runtime_names_no_message_type_of_the_case_study():
    packages = [p.encode() for p in _case_study_packages()]
    hits = []
    for path in _runtime_files():
        for number, line in enumerate(path.read_bytes().splitlines(), 1):
            if any(package in line for package in packages):
                hits.append(f"{path.relative_to(ROOT)}:{number}: {line.decode(errors='replace')}")
    assert hits == [], "the case study's message types, named in the framework:\n" + "\n".join(hits)


def _python_sources(folder: Path) -> list[Path]:
    return sorted(p for p in folder.rglob("*.py") if "__pycache__" not in p.parts)


def _lines_with(text: str, folder: Path) -> list[str]:
    return [f"{path}:{number}: {line.strip()}"
            for path in _python_sources(folder)
            for number, line in enumerate(path.read_text().splitlines(), 1) if text in line]


def test_node_statistics_are_read_by_field_in_the_fleet():
    """The live verdict and the launcher read `NodeStatistics` fields; a renamed counter is
    then a type error, not a silent zero."""
    assert _lines_with("stats.get(", RUNTIME / "fleet") == []


def test_production_never_reads_its_own_source():
    """The reduction's rules fingerprint is a test (tests/checker/test_reduction_rules.py);
    an install without sources works. (The load-time lint reads the *user's* node source
    with `inspect.getsourcelines`, which is its job.)"""
    assert _lines_with("inspect.getsource(", ROOT / "twinfleet") == []


def test_the_rules_catch_what_they_look_for(tmp_path):
    (tmp_path / "m.py").write_text("x = stats.get('gaps', 0)\ny = inspect.getsource(f)\n")
    assert len(_lines_with("stats.get(", tmp_path)) == 1
    assert len(_lines_with("inspect.getsource(", tmp_path)) == 1


def test_no_test_finds_processes_to_end_by_their_command_line() -> None:
    """Tests end only what they started (tests/integration/itest_support.py `spawned_by`):
    a scan of every process's command line once ended another xdist worker's fleet that ran
    the same shipped scenario."""
    needles = ("processes_mentioning", "pkill", "killall", "pgrep")
    offenders = [f"{path.relative_to(ROOT)}: {needle}"
                 for path in sorted((ROOT / "tests").rglob("*.py"))
                 if path.name != Path(__file__).name
                 for needle in needles if needle in path.read_text()]
    assert offenders == []
