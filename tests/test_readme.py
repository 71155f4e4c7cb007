"""The README's walk-through ("Writing a node") runs as it is written.

Every fenced block preceded by ``<!-- file: NAME -->`` belongs to file NAME; the
blocks of one file are joined in README order, written to a fresh directory and
the walk-through's own pytest file is run there in a child process (its live test
starts real node processes over Zenoh on 127.0.0.1, scouting off).
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.support import ROOT, child_env

BLOCK = re.compile(r"<!-- file: (?P<name>[\w.]+) -->\n```python\n(?P<code>.*?)```", re.S)


def readme_files() -> dict[str, str]:
    """File name -> the code of its blocks, joined in README order."""
    files: dict[str, list[str]] = {}
    for m in BLOCK.finditer((ROOT / "README.md").read_text()):
        files.setdefault(m["name"], []).append(m["code"])
    return {name: "\n\n".join(parts) for name, parts in files.items()}


def test_the_walk_through_has_its_files():
    files = readme_files()
    assert set(files) == {"cells.py", "test_cells.py"}
    assert files["test_cells.py"].count("def test_") == 3


@pytest.mark.slow
@pytest.mark.fleet
@pytest.mark.timeout(120)
def test_the_readme_walk_through_runs(tmp_path: Path):
    for name, code in readme_files().items():
        (tmp_path / name).write_text(code)
    env = child_env()
    env["PYTHONPATH"] = f"{tmp_path}:{env['PYTHONPATH']}"
    run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                          "-rA", "test_cells.py"], cwd=tmp_path, env=env, capture_output=True,
                         text=True, timeout=110)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "3 passed" in run.stdout
    assert "len(keeper.inside) <= 1' is false at t=100 ms" in run.stdout  # the race, printed
