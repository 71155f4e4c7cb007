"""Finished cases of an experiment, kept in its output directory so that a rerun skips them.

After a case (checker, prediction and every live run) is done, `save_case`
writes `OUT/cases/<case>.json`: the case's `Row`, its live runs, the
checker's predicted arrival times and the runs repeated, with a fingerprint
of what decides them — the scenario file's content and every option that
changes a result. `load_case` gives the case back only when the fingerprint
is the same, so an experiment rerun with the same command after Ctrl-C, a
crash or a reboot continues with the first unfinished case, and a changed
option or scenario runs the case again. A half-done case is not kept: its
live runs are repeated from the first.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, final

from twinfleet.robots.live import LiveRunResult
from twinfleet.robots.paper import paper_row
from twinfleet.robots.table import CheckCell, LiveSummary, Prediction, Row

CASE_FORMAT = "twinfleet-experiment-case/1"


@final
@dataclass(frozen=True, slots=True)
class FinishedCase:
    """A case as an earlier run of the experiment left it."""

    row: Row
    runs: list[LiveRunResult]
    predicted_arrival_ms: dict[str, int | None]
    retried: list[tuple[str, int, str]]
    prediction_key: str | None = None  # the fingerprint of the prediction's options


def fingerprint(scenario: str | Path, options: dict[str, Any]) -> str:
    """A digest of the scenario file's content and the options that decide a case."""
    text = Path(scenario).read_bytes()
    blob = json.dumps(options, sort_keys=True, default=str).encode()
    return hashlib.blake2b(text + b"\0" + blob, digest_size=12).hexdigest()


def case_path(out: Path, case: str) -> Path:
    """Where a finished case is kept."""
    return out / "cases" / f"{case}.json"


def save_case(out: Path, key: str, done: FinishedCase) -> Path:
    """Keep a finished case under its fingerprint `key`."""
    row = done.row
    doc = {"format": CASE_FORMAT, "fingerprint": key, "prediction": done.prediction_key,
           "row": {"case": row.case, "scenario": row.scenario, "profile": row.profile,
                   "scan_ms": row.scan_ms, "robots": [list(r) for r in row.robots],
                   "checks": {sem: {**dataclasses.asdict(c), "status": c.status.value}
                              for sem, c in row.checks.items()},
                   "live": None if row.live is None else dataclasses.asdict(row.live),
                   "prediction": (None if row.prediction is None
                                  else dataclasses.asdict(row.prediction))},
           "runs": [dataclasses.asdict(r) for r in done.runs],
           "predicted_arrival_ms": done.predicted_arrival_ms,
           "retried": [list(r) for r in done.retried]}
    path = case_path(out, row.case)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(doc, indent=1) + "\n")
    tmp.replace(path)  # a case file is whole or absent, even if the machine stops here
    return path


def load_case(out: Path, case: str, key: str) -> FinishedCase | None:
    """The case kept under fingerprint `key`, or None (none kept, another fingerprint, or
    unreadable: the case is run again)."""
    try:
        doc = json.loads(case_path(out, case).read_text())
        if doc.get("format") != CASE_FORMAT or doc.get("fingerprint") != key:
            return None
        return _finished(doc)
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _finished(doc: dict[str, Any]) -> FinishedCase:
    r = doc["row"]
    row = Row(case=r["case"], scenario=r["scenario"], profile=r["profile"], scan_ms=r["scan_ms"],
              robots=tuple((name, float(v), int(w)) for name, v, w in r["robots"]),
              checks={sem: CheckCell(**c) for sem, c in r["checks"].items()},
              live=None if r["live"] is None else LiveSummary(**r["live"]),
              paper=paper_row(r["case"]),
              prediction=None if r["prediction"] is None else Prediction(**r["prediction"]))
    names = {f.name for f in dataclasses.fields(LiveRunResult)}
    runs = []
    for run in doc["runs"]:
        fields = {k: v for k, v in run.items() if k in names}
        fields["collisions"] = [tuple(c) for c in fields.get("collisions", [])]
        fields["failed_nodes"] = tuple(fields.get("failed_nodes", ()))
        fields["stuck"] = tuple(fields.get("stuck", ()))
        runs.append(LiveRunResult(**fields))
    return FinishedCase(row, runs, dict(doc["predicted_arrival_ms"]),
                        [(c, int(s), why) for c, s, why in doc["retried"]],
                        doc.get("prediction"))
