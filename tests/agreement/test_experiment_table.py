"""The experiment table: columns, wording, agreement rules, and the paper's figures."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import pytest

from twinfleet.robots.experiment import scenario_row
from twinfleet.robots.paper import PAPER, paper_row
from twinfleet.robots.table import (
    CheckCell,
    LiveSummary,
    Row,
    columns,
    markdown_header,
    to_csv,
    to_markdown,
)
from twinfleet.runtime.scenario.spec import load_scenario

pytestmark = pytest.mark.offline  # starts no fleet, opens no Zenoh session

ROOT = Path(__file__).resolve().parents[2]
BOTH = ("ros", "rebeca")


def _row(ros: str = "holds", detail: str = "every property holds", collisions: int = 0,
         runs: int = 4, unarrived: int = 0) -> Row:
    row = Row("c1a", "launch/c1a.yaml", "fixed", 100, (("r1", 0.5, 1500), ("r2", 1.0, 2000)),
              paper=paper_row("c1a"))
    row.checks["ros"] = CheckCell("ros", ros, detail, 41608, 128800, 128801, 5.5,
                                  None if ros == "holds" else "out/t.json")
    row.checks["rebeca"] = CheckCell("rebeca", "holds", "every property holds", 18568, 43166,
                                     43167, 2.2)
    row.live = LiveSummary(runs, 5.0)
    for k in range(runs):
        collided = k < collisions
        arrived = not collided and k >= collisions + unarrived
        row.live.add(passed=arrived and not collided, collision=collided, all_arrived=arrived,
                     node_failed=False, wall_s=6.0)
    return row


def test_csv_has_one_column_group_per_semantics_and_the_paper_figures():
    cols = columns(BOTH)
    for sem in BOTH:
        assert [c for c in cols if c.startswith(sem + "_")] == [
            f"{sem}_result", f"{sem}_states", f"{sem}_transitions", f"{sem}_rmc_transitions",
            f"{sem}_time_s", f"{sem}_trace"]
    assert {"case", "scan_ms", "parameters", "simulations", "agreement", "paper_result",
            "paper_states", "paper_transitions", "paper_simulations"} <= set(cols)
    assert columns(("ros",)) == [c for c in cols if not c.startswith("rebeca_")]


def test_csv_values_are_raw_and_parse_back():
    text = to_csv([_row()], BOTH)
    (rec,) = list(csv.DictReader(io.StringIO(text)))
    assert list(rec) == columns(BOTH)
    assert rec["ros_states"] == "41608" and rec["ros_rmc_transitions"] == "128801"
    assert rec["parameters"] == ".5/1500 1/2000"
    assert rec["simulations"] == "4/4 passed, 0/4 failed"
    assert (rec["paper_result"], rec["paper_states"], rec["paper_transitions"]) == (
        "satisfied", "19264", "43814")
    assert rec["paper_simulations"] == "5/5 passed, 0/5 failed"


def test_markdown_table_has_header_separator_and_formatted_counts():
    lines = to_markdown([_row()], BOTH).splitlines()
    assert len(lines) == 3
    head = [c.strip() for c in lines[0].strip("|").split("|")]
    assert head == markdown_header(BOTH)
    assert lines[1] == "|" + "|".join("---" for _ in head) + "|"
    cells = [c.strip() for c in lines[2].strip("|").split("|")]
    assert len(cells) == len(head)
    assert cells[head.index("ros: states")] == "41,608"
    assert cells[head.index("ros: transitions / RMC-style")] == "128,800 / 128,801"
    assert cells[head.index("paper: states / transitions")] == "19,264 / 43,814"
    assert cells[head.index("simulations")] == "4/4 passed, 0/4 failed"


def test_markdown_escapes_pipes():
    row = _row(ros="unknown", detail="max-states 5 | reached")
    assert "max-states 5 \\| reached" in to_markdown([row], BOTH)


@pytest.mark.parametrize(("ros", "detail", "collisions", "unarrived", "expected"), [
    ("holds", "every property holds", 0, 0, "agree: no collision"),
    ("holds", "every property holds", 1, 0, "CONTRADICTION: live collision in 1/4"),
    ("holds", "every property holds", 0, 2, "CONTRADICTION?: 2/4 runs did not finish"),
    ("violated", "no_collision", 3, 0, "agree: collision live in 3/4"),
    ("violated", "no_collision", 0, 0, "collision not seen live (0/4); see trace"),
    ("violated", "no_livelock", 0, 1, "checker: no_livelock violated; live failed 1/4"),
    ("unknown", "max-states 10 reached", 2, 0, "no verdict; live collisions in 2/4"),
])
def test_agreement_compares_live_runs_with_the_ros_verdict(ros, detail, collisions, unarrived,
                                                           expected):
    row = _row(ros, detail, collisions, unarrived=unarrived)
    assert row.agreement.startswith(expected)
    assert row.contradiction == expected.startswith("CONTRADICTION")


def test_live_summary_wording_and_failure_reasons():
    s = LiveSummary(20, 5.0)
    s.add(passed=True, collision=False, all_arrived=True, node_failed=False, wall_s=6)
    s.add(passed=False, collision=True, all_arrived=False, node_failed=False, wall_s=3)
    s.add(passed=False, collision=False, all_arrived=False, node_failed=False, wall_s=40)
    assert s.simulations == "1/3 passed, 2/3 failed (stopped after 3 of 20)"
    assert s.failures == "collision 1, not arrived 1"
    assert LiveSummary(0, 1.0).failures == "-"


def test_check_cell_result_uses_the_papers_words():
    assert CheckCell("ros", "holds", "", 1, 1, 2, 0.1).result == "satisfied"
    assert CheckCell("ros", "violated", "no_collision", 1, 1, 2, 0.1).result == (
        "violated: no_collision")
    assert CheckCell("ros", "unknown", "max-states 9 reached", 1, 1, 2, 0.1).result == (
        "unknown: max-states 9 reached")


@pytest.mark.parametrize("case", ["c1a", "c1b", "c1c", "c2a", "c2b", "c2c"])
@pytest.mark.parametrize("suffix", ["", "_rebeca"])
def test_paper_rows_match_the_launch_files(case, suffix):
    path = ROOT / "twinfleet" / "launch" / f"{case}{suffix}.yaml"
    row = scenario_row(path, load_scenario(path))
    paper = PAPER[f"{case}{suffix}"]
    assert row.paper is paper and paper.case.lower() == case
    assert row.scan_ms == paper.scan_ms
    assert tuple((v, w) for _, v, w in row.robots) == paper.robots


def test_paper_rows_hold_the_reference_figures():
    assert (PAPER["c1a"].states, PAPER["c1a"].transitions, PAPER["c1a"].passed) == (
        19264, 43814, 5)
    assert (PAPER["c2c"].result, PAPER["c2c"].states, PAPER["c2c"].transitions) == (
        "collision", 1740, 3727)
    assert PAPER["c2a"].simulations == "2/5 passed, 3/5 failed"
    assert paper_row("headon") is None
