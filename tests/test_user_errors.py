"""A new user's mistakes get one line that says what to change, in one prefix style.

The station system (tests/data/station) with properties that read a misspelt
state field, or a parameter instead of a state field; a scenario whose lint
warns, with --strict; and a handful of commands given bad input.
"""

from __future__ import annotations

import contextlib
import io
import shutil
from pathlib import Path

import pytest
import yaml

from twinfleet.cli import main

STATION = Path(__file__).resolve().parent / "data" / "station"


def run(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(argv))
    return code, out.getvalue(), err.getvalue()


@pytest.fixture
def project(tmp_path: Path) -> Path:
    shutil.copy(STATION / "station_nodes.py", tmp_path)
    return tmp_path


def scenario(project: Path, expr: str) -> Path:
    a = {"name": "a", "class": "station_nodes:Asker"}
    doc = {"name": "mistakes",
           "nodes": [{"name": "station", "class": "station_nodes:Station"}, a],
           "properties": [{"name": "p", "kind": "invariant", "expr": expr}]}
    path = project / "mistakes.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


@pytest.mark.parametrize("command", ["check", "launch"])
def test_a_misspelt_state_field_lists_the_real_fields(project: Path, command: str) -> None:
    code, _, err = run(command, str(scenario(project, "not a.finished")))
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert err.startswith(f"twinfleet {command}: ") and "has no field 'finished'" in err
    assert "its fields: asked, charging" in err


def test_a_parameter_read_as_state_says_properties_read_state(project: Path) -> None:
    source = (project / "station_nodes.py").read_text()  # a module of its own: imported anew
    (project / "slot_nodes.py").write_text(source.replace(
        "class Asker(Node):", "@dataclass(frozen=True)\nclass AskerParams:\n    slots: int = 1\n\n\n"
        "class Asker(Node):\n    Params = AskerParams\n", 1))
    path = scenario(project, "a.slots > 0")
    path.write_text(path.read_text().replace("station_nodes:Asker", "slot_nodes:Asker"))
    code, _, err = run("check", str(path))
    assert code == 2, err
    assert "slots is a parameter of a: properties read the nodes' states, not their " \
           "parameters" in err


def test_strict_turns_a_lint_warning_into_exit_2(project: Path) -> None:
    lonely = project / "lonely.yaml"  # a robot that calls a service nobody serves
    lonely.write_text(yaml.safe_dump({"name": "lonely", "nodes": [
        {"name": "a", "class": "station_nodes:Asker"}], "live": {"wall_timeout_s": 1}}))
    for command in ("check", "launch"):
        code, _, err = run(command, str(lonely), "--strict")
        assert code == 2, err
        assert "calls service /book but no node serves it" in err
        assert f"twinfleet {command}: --strict: 2 lint warning(s) fail" in err
    code, _, _ = run("check", str(lonely), "--quiet")  # without --strict: warned, checked
    assert code == 1


@pytest.mark.parametrize("argv", [
    ["check", "no_such_scenario"], ["launch", "no_such_scenario"],
    ["render", "no_such.json", "-o", "x.png"], ["trace", "show", "no_such.json"],
    ["replay", "no_such.json"], ["param", "set", "r1", "speed", "0.4"],
])
def test_every_command_says_its_name_first(argv: list[str], tmp_path: Path,
                                          monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    code, _, err = run(*argv)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1, err
    words = argv[0] if argv[0] not in ("trace", "param") else " ".join(argv[:2])
    assert lines[0].startswith(f"twinfleet {words}: "), lines[0]
