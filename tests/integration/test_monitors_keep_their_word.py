"""Monitors find what they promise: an echo started before the fleet, a played recording, and
a `topic pub` of the wrong type refused (or, forced, named as external input by the verdict).

Each test has its own fleet registry (a private XDG_RUNTIME_DIR); no command gives --connect.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from itest_support import ROOT, child_env, launch_in, poll, run_cli_in, stop_launch

pytestmark = [pytest.mark.slow, pytest.mark.timeout(120)]

DEMO = str(ROOT / "twinfleet" / "launch" / "demo.yaml")


def _start(runtime_dir: Path, *args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "twinfleet", *args], env=child_env(runtime_dir),
                            cwd=ROOT, text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True)


def _finish(proc: subprocess.Popen, timeout: float) -> tuple[str, str]:
    try:
        return proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate(timeout=5)
        raise AssertionError(f"{proc.args} did not end: {out} {err}") from None


def test_echo_waits_for_the_fleet_and_pub_checks_the_type(tmp_path: Path) -> None:
    runtime = tmp_path / "xdg"
    runtime.mkdir()
    echo = _start(runtime, "topic", "echo", "/chatter", "--once", "--wait",
                  "--wait-timeout", "60")
    log = tmp_path / "demo.log"
    proc = None
    try:
        # the echo says once that it waits (and does not exit) before the fleet exists
        first = echo.stderr.readline()
        assert first.startswith("waiting for a fleet to be launched on this machine"), first
        assert echo.poll() is None
        proc = launch_in(runtime, log, DEMO, "--timeout", "20")
        out, err = _finish(echo, 40)
        assert echo.returncode == 0, (out, err)
        assert "data: hello" in out, out
        assert err.count("waiting for a fleet") == 0  # said once: the line read above

        wrong = run_cli_in(runtime, "topic", "pub", "/chatter", "std_msgs/Empty")
        assert wrong.returncode == 2, wrong
        line = wrong.stderr.strip()
        assert len(line.splitlines()) == 1, line
        assert "/chatter carries std_msgs/String" in line and "not std_msgs/Empty" in line, line
        assert "published" not in wrong.stdout

        forced = run_cli_in(runtime, "topic", "pub", "/chatter", "std_msgs/Empty", "--force")
        assert forced.returncode == 0, forced
        assert "sending it anyway (--force)" in forced.stderr
        assert poll(lambda: "result:" in log.read_text(), 40), log.read_text()
        text = log.read_text()
        assert "result: PASSED" in text, text
        assert "external input: listener refused 1 samples an operator's command sent" in text
    finally:
        if echo.poll() is None:
            echo.kill()
        if proc is not None:
            stop_launch(proc)


def test_monitors_find_a_played_recording_without_flags(tmp_path: Path) -> None:
    runtime = tmp_path / "xdg"
    runtime.mkdir()
    bag = tmp_path / "run.mcap"
    recorded = run_cli_in(runtime, "record", DEMO, "-o", str(bag), "--duration", "2",
                          timeout=60)
    assert recorded.returncode in (0, 3), recorded  # 3: a recording cut short is inconclusive
    assert bag.is_file()
    play = _start(runtime, "play", str(bag), "--wait", "30")
    try:
        assert poll(lambda: run_cli_in(runtime, "node", "list").returncode == 0, 20)
        listed = run_cli_in(runtime, "topic", "list", "-t")
        assert listed.returncode == 0, listed
        assert "/chatter [std_msgs/String]" in listed.stdout, listed.stdout
        echoed = run_cli_in(runtime, "topic", "echo", "/chatter", "--once", timeout=30)
        assert echoed.returncode == 0, echoed
        assert "data: hello" in echoed.stdout, echoed.stdout
        nodes = run_cli_in(runtime, "node", "list")
        assert "/play" in nodes.stdout.split() or "play" in nodes.stdout, nodes.stdout
    finally:
        if play.poll() is None:
            play.terminate()
        _finish(play, 20)


def test_operator_input_that_nodes_take_is_named_by_the_verdict(tmp_path: Path) -> None:
    runtime = tmp_path / "xdg"
    runtime.mkdir()
    log = tmp_path / "demo.log"
    proc = launch_in(runtime, log, DEMO, "--timeout", "15")
    try:
        heard = run_cli_in(runtime, "topic", "echo", "/chatter", "--once", "--wait",
                           "--wait-timeout", "40", timeout=60)
        assert heard.returncode == 0, heard
        sent = run_cli_in(runtime, "topic", "pub", "/chatter", "std_msgs/msg/String",
                          "{data: from outside}")
        assert sent.returncode == 0, sent
        called = run_cli_in(runtime, "service", "call", "/add_two_ints",
                            "example_interfaces/srv/AddTwoInts", "{a: 1, b: 2}")
        assert called.returncode == 0 and "sum: 3" in called.stdout, called
        assert poll(lambda: "result:" in log.read_text(), 40), log.read_text()
        text = log.read_text()
        assert "result: PASSED" in text, text
        assert ("took external input (from outside the fleet; the checked model has no such "
                "input): adder: 1 on /add_two_ints from an operator's command (topic pub, "
                "service call); listener: 1 on /chatter from an operator's command") in text, text
    finally:
        stop_launch(proc)
