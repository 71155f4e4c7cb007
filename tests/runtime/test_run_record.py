"""The run record: JSON lines, one flushed per event, readable after a crash."""

from __future__ import annotations

import json
from dataclasses import dataclass
from enum import Enum
from pathlib import Path

from twinfleet.runtime.fleet.run_record import RunRecord, plain, read_run_record, versions


@dataclass(frozen=True)
class Inner:
    cell: tuple[int, int]
    data: bytes


class Mode(Enum):
    FAST = "fast"


def test_each_event_is_one_complete_line_on_disk_as_soon_as_it_is_written(tmp_path: Path) -> None:
    path = tmp_path / "run.jsonl"
    record = RunRecord(path)
    record.write("start", scenario="x.yaml", seed=3)
    first = path.read_text().splitlines()  # read while the record is still open
    record.write("node_exit", node="r1", code=-9, last_lines=["a", "b"])
    record.close()
    record.write("ignored", after="close")
    events = read_run_record(path)
    assert [json.loads(line)["event"] for line in first] == ["start"]
    assert [e["event"] for e in events] == ["start", "node_exit"]
    assert events[1]["code"] == -9 and events[1]["last_lines"] == ["a", "b"]
    assert events[0]["t"] <= events[1]["t"] and events[0]["wall"] > 0


def test_a_torn_last_line_is_skipped(tmp_path: Path) -> None:
    path = tmp_path / "run.jsonl"
    path.write_text('{"event": "start", "t": 0}\n{"event": "node_ex')
    assert read_run_record(path) == [{"event": "start", "t": 0}]


def test_values_become_plain_json() -> None:
    value = {"msg": Inner((1, 2), b"\x01\xff"), "mode": Mode.FAST, "set": frozenset({1}),
             "obj": object, 3: None}
    out = plain(value)
    assert out["msg"] == {"cell": [1, 2], "data": "01ff"}
    assert out["mode"] == "fast" and out["set"] == [1] and out["3"] is None
    assert isinstance(out["obj"], str)
    json.dumps(out)


def test_versions_name_python_and_the_dependencies() -> None:
    found = versions()
    assert {"python", "eclipse-zenoh", "msgpack", "numpy", "pyyaml", "twinfleet"} <= set(found)


def test_runs_append_to_one_file(tmp_path: Path) -> None:
    path = tmp_path / "runs.jsonl"
    for run in range(2):
        record = RunRecord(path)
        record.write("start", run=run)
        record.write("summary", ok=True)
        record.close()
    assert [(e["event"], e.get("run")) for e in read_run_record(path)] == [
        ("start", 0), ("summary", None), ("start", 1), ("summary", None)]
