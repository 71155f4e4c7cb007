"""`benchmarks/docs_figures.py` reads the docs' figures and compares them with what runs.

Here on the cheapest figures (the station's states, milliseconds each); the full run
(every figure, minutes) is the script itself.
"""

from __future__ import annotations

import importlib.util
import re
import shutil
import sys
from pathlib import Path
from types import ModuleType

import pytest

pytestmark = pytest.mark.timeout(120)

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def figures() -> ModuleType:
    spec = importlib.util.spec_from_file_location("docs_figures", ROOT / "benchmarks" /
                                                  "docs_figures.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["docs_figures"] = module
    spec.loader.exec_module(module)
    return module


def test_a_cell_reads_as_the_doc_means_it(figures: ModuleType) -> None:
    parse, claim = figures.parse_claim, figures.Claim
    assert parse("holds, **18,527 / 43,077**", rmc=True) == claim("holds", 18_527, 43_077, True)
    assert parse("**collision**, 10,297 / 23,821 (t=27.4 s)", rmc=True) == claim(
        "violated", 10_297, 23_821, True, 27_400.0, 100.0)
    assert parse("collision, **2,901 / 6,429** at t = 9,832 ms", rmc=True) == claim(
        "violated", 2_901, 6_429, True, 9_832.0, 1.0)
    assert parse("**5,516**", rmc=False) == claim(states=5_516)
    assert parse("393¹ / 400", rmc=False) == claim(states=393, transitions=400)  # a footnote mark
    for no_count in ("> 262,602 (no answer in 60 s)", "(skipped after 8)", "", "2.4"):
        assert parse(no_count, rmc=False) is None


@pytest.mark.slow  # 5 s on a loaded machine: it writes the scaling benchmark's scenarios
def test_every_table_and_named_sentence_is_found(figures: ModuleType, capsys) -> None:
    assert figures.main(["--list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) >= 90
    said = {re.sub(r":\d+ ", " ", " ".join(line.split()), count=1) for line in lines}
    for expected in ("docs/results.md c1a_rebeca holds, 18,527 / 43,077",
                     "README.md c1a (por) 5,516",
                     "docs/reduction.md c1a_rebeca 18,527 / 43,076"):
        assert expected in said


@pytest.mark.slow  # a few seconds: it runs `twinfleet check` twice
def test_the_station_figures_are_the_same(figures: ModuleType, capsys) -> None:
    assert figures.main(["--only", "station"]) == 0
    *rows, last = capsys.readouterr().out.splitlines()
    assert len(rows) == 2 and all(row.startswith("docs/reduction.md:") and row.endswith(" same")
                                  for row in rows)
    assert last == "2 of 2 figures the same"


@pytest.mark.slow
def test_an_edited_figure_differs(figures: ModuleType, tmp_path: Path, capsys) -> None:
    shutil.copy(ROOT / "README.md", tmp_path / "README.md")
    shutil.copytree(ROOT / "docs", tmp_path / "docs")
    reduction = tmp_path / "docs" / "reduction.md"
    text = reduction.read_text()
    assert text.count("| station (tests/data) | 31 |") == 1
    reduction.write_text(text.replace("| station (tests/data) | 31 |", "| station (tests/data) | 32 |"))
    assert figures.main(["--only", "station", "--docs", str(tmp_path)]) == 1
    out = capsys.readouterr().out
    assert "doc says 32" in out and "measured 31" in out and "DIFFERS" in out
    assert out.endswith("1 of 2 figures the same\n")
