"""A sweep's results as tables: Markdown (to read), CSV (to plot), JSON (to process).

One row per point, in the grid's order: the point's values, then the verdict, the
violated property, states, transitions, the check's wall time and the fleet time of the
first violation (the last step of the counterexample; empty when nothing is violated).
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Sequence
from typing import Any

from twinfleet.sweep.grid import Axis, format_value
from twinfleet.sweep.point import PointResult

COLUMNS = ("verdict", "violated", "states", "transitions", "time_s", "violation_time_ms")


def rows(axes: Sequence[Axis], results: Sequence[PointResult]) -> list[list[str]]:
    """The table's cells as text: a header row, then one row per point."""
    table = [[a.name for a in axes] + list(COLUMNS)]
    for r in results:
        values = dict(r.point)
        table.append([format_value(values[a.name]) for a in axes] + [
            r.verdict, r.violated or "", str(r.states), str(r.transitions), f"{r.time_s:.2f}",
            "" if r.violation_time_ms is None else str(r.violation_time_ms)])
    return table


def markdown(title: str, axes: Sequence[Axis], results: Sequence[PointResult]) -> str:
    """A Markdown table with a title line and a count of each verdict."""
    table = rows(axes, results)
    counts: dict[str, int] = {}
    for r in results:
        counts[r.verdict] = counts.get(r.verdict, 0) + 1
    lines = [f"# {title}", "",
             f"{len(results)} points: " + ", ".join(f"{n} {v}" for v, n in sorted(counts.items())),
             "", "| " + " | ".join(table[0]) + " |", "|" + "---|" * len(table[0])]
    lines += ["| " + " | ".join(cell.replace("|", "\\|") for cell in row) + " |"
              for row in table[1:]]
    errors = [(r.point, r.reason) for r in results if r.verdict == "error"]
    if errors:
        lines += ["", "Points that could not be checked:", ""]
        lines += [f"- {' '.join(f'{n}={format_value(v)}' for n, v in p)}: {why}"
                  for p, why in errors]
    return "\n".join(lines) + "\n"


def csv_text(axes: Sequence[Axis], results: Sequence[PointResult]) -> str:
    """The table as CSV."""
    buffer = io.StringIO()
    csv.writer(buffer, lineterminator="\n").writerows(rows(axes, results))
    return buffer.getvalue()


def json_text(scenario: str, axes: Sequence[Axis], results: Sequence[PointResult],
              settings: dict[str, Any]) -> str:
    """The table as JSON: the scenario, the axes, the settings and one record per point
    (values keep their types: numbers stay numbers)."""
    doc = {"scenario": scenario, "settings": settings,
           "axes": [{"name": a.name, "sets": a.target.value, "values": list(a.values)}
                    for a in axes],
           "points": [{"params": dict(r.point), **{k: v for k, v in r.to_json().items()
                                                   if k != "point"}} for r in results]}
    return json.dumps(doc, indent=1, default=str) + "\n"
