"""Any system's counterexample, read and drawn: `trace show` and the sequence chart.

The system has no map: a charging station with one slot that two robots book
(tests/data/station). Its counterexample is known by hand: 8 steps, both
robots granted before either plugs in, the second plug-in breaks the
invariant.
"""

from __future__ import annotations

import contextlib
import io
import json
import re
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from twinfleet.cli import main

STATION = Path(__file__).resolve().parent / "data" / "station" / "station.yaml"


def run(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(argv))
    return code, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def trace(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("station") / "station.trace.json"
    code, out, err = run("check", str(STATION), "--trace-out", str(path), "--quiet")
    assert code == 1, out + err
    return path


def test_trace_show_prints_every_step_and_the_violated_property_last(trace: Path) -> None:
    code, out, err = run("trace", "show", str(trace))
    assert code == 0, err
    lines = out.splitlines()
    steps = [line for line in lines if re.match(r"^\s+\d+  t=", line)]
    assert [int(s.split()[0]) for s in steps] == list(range(1, 9))
    assert [s.split()[3] for s in steps] == [
        "a.tick", "b.tick", "station.book", "a.on_answer", "station.book", "b.on_answer",
        "station.on_plugged", "station.on_plugged"]
    assert "sends request on /book to station.book" in out
    assert "state station: in_use 1 -> 2" in out
    assert lines[-1].startswith("violated: one_at_a_time: invariant 'station.in_use <= 1'")
    code, out, _ = run("trace", "show", str(trace), "--json")
    walked = json.loads(out)
    assert walked["nodes"] == ["station", "a", "b"] and len(walked["steps"]) == 8
    assert walked["steps"][2]["sent"][0]["kind"] == "reply"


def test_trace_show_refuses_a_file_that_is_not_a_trace(tmp_path: Path) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    code, _, err = run("trace", "show", str(bad))
    assert code == 2 and err.startswith("twinfleet trace show: ") and len(err.splitlines()) == 1


def test_a_mapless_trace_is_drawn_as_a_sequence_chart_png_and_svg(trace: Path,
                                                                  tmp_path: Path) -> None:
    png, svg = tmp_path / "bug.png", tmp_path / "bug.svg"
    for path in (png, svg):
        code, out, err = run("render", str(trace), "-o", str(path))
        assert code == 0 and "sequence chart, 8 steps, 3 lifelines" in out, out + err
    text = svg.read_text()
    heads = re.findall(r'<text x="\d+" y="20" fill="rgb\(0,0,0\)">([^<]+)</text>', text)
    assert heads == ["station", "a", "b"]  # one lifeline per node, named at the top
    # an arrow per handled message: two bookings, two answers, two plug-ins (ticks are timers)
    assert text.count('marker-end="url(#head)"') == 6
    assert "violated: one_at_a_time" in text
    arr = np.asarray(Image.open(png).convert("RGB"))
    red = (arr[..., 0] > 150) & (arr[..., 1] < 90) & (arr[..., 2] < 90)  # text is antialiased
    assert red[-60:].sum() > 50  # the violation at the foot
    grey = np.all(arr == (150, 150, 150), axis=-1)
    columns = np.flatnonzero(grey.sum(axis=0) > 150)  # the lifelines, top to bottom
    assert len(columns) == 3, columns
