"""`python -m twinfleet.robots experiment` end to end on the tiny head-on scenario (real processes)."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
import time
from pathlib import Path

import pytest

from twinfleet.robots.table import columns, markdown_header

ROOT = Path(__file__).resolve().parents[2]


def _run(*args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "twinfleet.robots", *args], cwd=ROOT, text=True,
                          capture_output=True, timeout=timeout,
                          env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})


@pytest.mark.slow
@pytest.mark.timeout(60)
def test_experiment_on_headon_writes_markdown_and_csv(tmp_path):
    started = time.monotonic()
    proc = _run("experiment", "headon", "--runs", "2", "--time-scale", "10",
                "--predict", "20", "--out", str(tmp_path))
    elapsed = time.monotonic() - started
    assert proc.returncode in (0, 1), proc.stderr
    assert elapsed < 40, f"took {elapsed:.1f} s"
    both = ("ros", "rebeca")
    head = "| " + " | ".join(markdown_header(both)) + " |"
    assert head in proc.stdout  # the table is printed too
    md = (tmp_path / "experiment.md").read_text()
    assert "twinfleet experiment headon --runs 2 --time-scale 10" in md
    assert head in md
    (row,) = list(csv.DictReader((tmp_path / "experiment.csv").open()))
    assert list(row) == columns(both)
    assert row["case"] == "headon" and row["runs"] == "2"
    assert int(row["passed"]) + int(row["failed"]) == 2
    assert row["simulations"] == f"{row['passed']}/2 passed, {row['failed']}/2 failed"
    assert row["predicted_simulations"] == "20"
    assert 0 <= float(row["predicted_low"]) <= float(row["predicted_pass"]) <= float(
        row["predicted_high"]) <= 1
    assert 0 <= float(row["agreement_p"]) <= 1
    assert "[experiment] headon: predicted P(pass)" in proc.stderr
    for sem in both:
        assert int(row[f"{sem}_states"]) > 0
        assert row[f"{sem}_result"].split(":")[0] in ("satisfied", "violated")
    data = json.loads((tmp_path / "experiment.json").read_text())
    runs = data["scenarios"]["headon"]["runs"]
    assert [r["seed"] for r in runs] == [1, 2]
    log = (tmp_path / "logs" / "headon.live.log").read_text()
    assert "===== run 1/2 of headon" in log and "[map_server]" in log
    assert "[map_server]" not in proc.stdout  # node output goes to the log, not the terminal
    assert "[experiment] headon live 2/2" in proc.stderr
    # The same command again keeps the finished case instead of running it.
    again = _run("experiment", "headon", "--runs", "2", "--time-scale", "10",
                 "--predict", "20", "--out", str(tmp_path), timeout=30)
    assert again.returncode == proc.returncode, again.stderr
    assert "headon: finished by an earlier run" in again.stderr
    assert "live 1/2" not in again.stderr
    assert list(csv.DictReader((tmp_path / "experiment.csv").open())) == [row]
    # Another prediction (here: more simulations) keeps the live runs, predicts again.
    other = _run("experiment", "headon", "--runs", "2", "--time-scale", "10",
                 "--predict", "30", "--out", str(tmp_path), timeout=30)
    assert "checks and live runs kept" in other.stderr and "live 1/2" not in other.stderr
    (again_row,) = list(csv.DictReader((tmp_path / "experiment.csv").open()))
    assert again_row["predicted_simulations"] == "30"
    assert again_row["simulations"] == row["simulations"]
    assert json.loads((tmp_path / "experiment.json").read_text())["scenarios"]["headon"][
        "runs"] == runs


def test_bad_arguments_exit_2(tmp_path):
    proc = _run("experiment", "headon", "--jobs", "2", "--out", str(tmp_path))
    assert proc.returncode == 2 and "--jobs" in proc.stderr
    proc = _run("demo", "--runs", "0", "--out", str(tmp_path))
    assert proc.returncode == 2 and "map server" in proc.stderr
    proc = _run("headon", "--timing", str(tmp_path / "none.yaml"), "--out", str(tmp_path))
    assert proc.returncode == 2 and "--timing" in proc.stderr
    proc = _run("headon", "--confidence", "1.5", "--out", str(tmp_path))
    assert proc.returncode == 2 and "--confidence" in proc.stderr


def test_checker_only_with_runs_0(tmp_path):
    proc = _run("headon", "--runs", "0", "--semantics", "ros", "--predict", "5", "--out",
                str(tmp_path))
    assert proc.returncode == 0, proc.stderr
    (row,) = list(csv.DictReader((tmp_path / "experiment.csv").open()))
    assert list(row) == columns(("ros",))
    assert row["runs"] == "0" and row["simulations"] == ""
    assert row["predicted_simulations"] == "5" and row["agreement_p"] == ""
    assert row["ros_trace"].endswith("headon.ros.trace.json")
    assert Path(row["ros_trace"]).is_file()


def test_register_adds_experiment_without_loading_the_live_runtime():
    code = ("import argparse, sys\n"
            "from twinfleet.robots.commands import register\n"
            "p = argparse.ArgumentParser(prog='twinfleet')\n"
            "register(p.add_subparsers(dest='command'))\n"
            "a = p.parse_args(['experiment', 'twinfleet/launch/c1a.yaml', '--runs', '3'])\n"
            "print(a.runs, a.time_scale, a.semantics, a.out, a.jobs, 'zenoh' in sys.modules)\n")
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, text=True, capture_output=True,
                          timeout=60, env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["3", "2.0", "both", "out/experiment", "1", "False"]


@pytest.mark.slow
@pytest.mark.timeout(90)
def test_ctrl_c_stops_and_still_writes_what_was_done(tmp_path):
    import signal

    proc = subprocess.Popen([sys.executable, "-m", "twinfleet.robots", "headon", "--runs",
                             "5", "--time-scale", "1", "--semantics", "ros", "--out",
                             str(tmp_path)], cwd=ROOT, text=True, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE,
                            env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    assert proc.stderr is not None
    seen = []
    for line in proc.stderr:  # wait for the first live run to finish
        seen.append(line)
        if "headon live 1/5" in line:
            break
    time.sleep(1.0)  # inside the second run
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, "".join(seen) + err
    md = (tmp_path / "experiment.md").read_text()
    assert "Interrupted (Ctrl-C)" in md
    assert "(stopped after 1 of 5)" in md
    (row,) = list(csv.DictReader((tmp_path / "experiment.csv").open()))
    assert row["runs"] == "1" and row["ros_result"]
