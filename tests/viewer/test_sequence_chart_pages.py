"""The sequence chart of a long trace stays readable: pages of `PAGE_STEPS` steps or a window
of steps, and messages still in flight drawn (dashed, to their target's lifeline at the
foot); `render` of a fleet without a map says so in the user's words."""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import pytest
from PIL import Image

from twinfleet.cli import main
from twinfleet.runtime.tools.view.sequence_chart import (
    PAGE_STEPS,
    Line,
    Text,
    layout,
    pages,
    save_chart,
    to_svg,
)

pytestmark = pytest.mark.offline  # starts no fleet, opens no Zenoh session

STATION = Path(__file__).resolve().parents[1] / "data" / "station" / "station.yaml"


def _step(i: int, node: str, sender: str, sent: list[dict] = ()) -> dict:  # type: ignore[assignment]
    return {"index": i, "node": node, "sender": sender, "handler": f"on_{i}", "args": f"m{i}",
            "name": f"/t{i}", "kind": "delivery", "time": 10 * i, "sent": list(sent),
            "changed": {}}


def _walk(n: int) -> dict:
    """`a` sends to `b` at step 1 (handled at step 3) and to `c` at step 2 (never handled);
    then `a` ticks to step `n`."""
    steps = [_step(1, "a", "a", [{"target": "b", "handler": "on_3", "args": "m3",
                                  "kind": "message", "name": "/t3"}]),
             _step(2, "a", "a", [{"target": "c", "handler": "on_x", "args": "lost",
                                  "kind": "message", "name": "/late"}]),
             _step(3, "b", "a")]
    steps += [_step(i, "a", "a") for i in range(4, n + 1)]
    return {"nodes": ["a", "b", "c"], "steps": steps, "property": "p", "message": "broken",
            "initial": {}}


def test_a_message_in_flight_at_the_end_is_drawn_dashed_to_its_target():
    chart = layout(_walk(4))
    dashed = [s for s in chart.shapes if isinstance(s, Line) and s.dashed]
    assert len(dashed) == 1 and dashed[0].arrow
    texts = [s.text for s in chart.shapes if isinstance(s, Text)]
    assert "in flight: /late (step 2)" in texts
    assert 'stroke-dasharray="6,4"' in to_svg(chart)


def test_a_window_starts_messages_sent_before_it_at_the_top():
    chart = layout(_walk(10), (3, 5))
    texts = [s.text for s in chart.shapes if isinstance(s, Text)]
    assert any(t.startswith("(step 1) /t3") for t in texts), texts
    assert "steps 3..5 of 10; at step 10, violated: p: broken" in texts
    assert not any(t.startswith(("1. ", "2. ", "6. ")) for t in texts)  # only steps 3..5


def test_a_long_trace_is_written_in_pages_of_readable_height(tmp_path):
    assert pages(130) == [(1, 60), (61, 120), (121, 130)] and PAGE_STEPS == 60
    assert pages(130, (5, 9)) == [(5, 9)] and pages(8) == [(1, 8)]
    written = save_chart(_walk(130), tmp_path / "long.png")
    assert [p.name for p in written] == ["long-1.png", "long-2.png", "long-3.png"]
    assert max(Image.open(p).height for p in written) < 2300


def run(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(argv))
    return code, out.getvalue(), err.getvalue()


def test_render_of_a_fleet_without_a_map_says_why_and_what_to_do(tmp_path):
    code, _, err = run("render", str(STATION), "-o", str(tmp_path / "x.png"))
    assert code == 2 and len(err.splitlines()) == 1, err
    assert "nothing to draw: the scenario names no scene" in err and "render T.json" in err
    trace = tmp_path / "t.json"
    assert run("check", str(STATION), "--trace-out", str(trace), "--quiet")[0] == 1
    code, out, err = run("render", str(trace), "-o", str(tmp_path / "w.svg"), "--steps", "2..4")
    assert code == 0 and "sequence chart, 8 steps, steps 2..4, 3 lifelines" in out, out + err
    code, _, err = run("render", str(trace), "-o", str(tmp_path / "w.svg"), "--steps", "2..40")
    assert code == 2 and "--steps 2..40: the trace has 8 steps" in err
