"""Every CLI error is one line naming what and where, exit 2, no traceback.

One test per error class: a bad file, a bad payload, a dead endpoint, a busy
endpoint, a missing fleet, a corrupt or truncated recording. The payload
tests run against a live demo fleet (found through the module's own fleet
registry); `--debug` shows the traceback the one line replaces.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
from itest_support import ROOT, launch_in, pick_free_port, poll, run_cli_in, stop_launch

pytestmark = [pytest.mark.slow, pytest.mark.timeout(120)]

DEMO = str(ROOT / "twinfleet" / "launch" / "demo.yaml")


@pytest.fixture(scope="module")
def runtime_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("xdg-runtime")


tf = run_cli_in


def one_line_error(result: subprocess.CompletedProcess[str], *needles: str) -> str:
    """Assert exit 2, exactly one line on stderr (`twinfleet COMMAND: ...`), no traceback
    anywhere."""
    assert result.returncode == 2, (result.returncode, result.stdout, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("twinfleet "), result.stderr
    assert lines[0].split(":")[0].split()[1] == result.args[3], lines[0]  # the command's name
    assert "Traceback" not in result.stdout + result.stderr
    assert ".rs:" not in lines[0], "a Rust source location leaked into the message"
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    return lines[0]


@pytest.fixture(scope="module")
def demo(runtime_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    log = tmp_path_factory.mktemp("demo") / "fleet.log"
    proc = launch_in(runtime_dir, log, DEMO, "--timeout", "100")
    poll(lambda: log.read_text().count("started") >= 4 or proc.poll() is not None, 40)
    try:
        assert proc.poll() is None, log.read_text()
        assert log.read_text().count("started") >= 4, log.read_text()
        yield log
    finally:
        stop_launch(proc)


@pytest.fixture
def recordings(tmp_path: Path) -> dict[str, Path]:
    """A file that is not MCAP at all, and a real recording cut short."""
    from mcap.writer import Writer

    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"this is not an mcap file" * 40)
    whole = tmp_path / "whole.mcap"
    with whole.open("wb") as f:
        writer = Writer(f)
        writer.start()
        schema = writer.register_schema("std_msgs/String", "jsonschema", b"{}")
        channel = writer.register_channel("/chatter", "msgpack", schema, {"key": "twinfleet/x/chatter"})
        for i in range(200):
            writer.add_message(channel, log_time=i * 1000, publish_time=i * 1000,
                               data=json.dumps({"i": i}).encode() * 5)
        writer.finish()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(whole.read_bytes()[: whole.stat().st_size // 2])
    return {"junk": junk, "cut": cut}


def test_bad_files(runtime_dir, tmp_path):
    one_line_error(tf(runtime_dir, "launch", str(tmp_path / "nope.yaml")), "nope.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("nodes: [ {name: a, class: x.y:Z} ]\n")
    one_line_error(tf(runtime_dir, "launch", str(bad)), "bad.yaml", "nodes[0].class")
    one_line_error(tf(runtime_dir, "view", "--trace", str(tmp_path / "none.json"), "--port", "0"),
                   "none.json")
    one_line_error(tf(runtime_dir, "bag", "info", str(tmp_path / "none.mcap")), "none.mcap",
                   "No such file")
    one_line_error(tf(runtime_dir, "launch", DEMO, "talker.periodms:=5"),
                   "'talker.periodms:=5'", "did you mean 'period_ms'")


def test_corrupt_and_truncated_recordings(runtime_dir, recordings):
    for path in recordings.values():
        for command in (["play", str(path), "--wait", "0"], ["bag", "info", str(path)],
                        ["export", str(path), "-o", str(path) + ".json.mcap"]):
            one_line_error(tf(runtime_dir, *command), str(path), "not a readable MCAP")


def test_missing_fleet(runtime_dir, tmp_path):
    empty = tmp_path / "empty-runtime"
    empty.mkdir(mode=0o700)
    line = one_line_error(tf(empty, "node", "list"), "no twinfleet fleet is running")
    assert "twinfleet launch" in line  # and how to start one
    one_line_error(tf(empty, "topic", "echo", "/poses", "--once"), "no twinfleet fleet")
    one_line_error(tf(empty, "record", "-o", str(tmp_path / "x.mcap")), "no twinfleet fleet")


def test_missing_fleet_by_name_while_another_runs(runtime_dir, demo):
    one_line_error(tf(runtime_dir, "node", "list", "--fleet", "demoo"),
                   "no fleet named 'demoo'", "demo (tcp/127.0.0.1:")


def test_dead_endpoint(runtime_dir, tmp_path):
    dead = f"tcp/127.0.0.1:{pick_free_port()}"
    one_line_error(tf(runtime_dir, "node", "list", "--connect", dead), dead, "cannot reach")
    one_line_error(tf(runtime_dir, "topic", "echo", "/x", "--connect", dead), dead)
    # A registry entry whose process lives but whose router is gone.
    stale = tmp_path / "stale-runtime"
    (stale / "twinfleet").mkdir(parents=True, mode=0o700)
    entry = {"format": "twinfleet-fleet/1", "fleet": "ghost", "endpoint": dead, "pid": os.getpid()}
    (stale / "twinfleet" / "ghost-1.json").write_text(json.dumps(entry))
    one_line_error(tf(stale, "node", "list"), dead, "its launcher does not answer")


def test_busy_endpoint(runtime_dir):
    with socket.socket() as held:
        held.bind(("127.0.0.1", 0))
        held.listen()
        busy = f"tcp/127.0.0.1:{held.getsockname()[1]}"
        one_line_error(tf(runtime_dir, "launch", DEMO, "--listen", busy), busy,
                       "Address already in use")


def test_bad_payloads(runtime_dir, demo):
    fleet = ("--fleet", "demo")
    one_line_error(tf(runtime_dir, "topic", "pub", "/chatter", "std_msgs/String", "hello", *fleet),
                   "YAML mapping")
    one_line_error(tf(runtime_dir, "topic", "pub", "/chatter", "std_msgs/String", "{dat: typo}",
                      *fleet), "unknown field 'dat'", "data")
    one_line_error(tf(runtime_dir, "topic", "pub", "/chatter", "std_msgs/String", "{data: [}",
                      *fleet), "not YAML")
    one_line_error(tf(runtime_dir, "topic", "pub", "/chatter", "std_msgs/Strin", "{data: x}",
                      *fleet), "unknown message type 'std_msgs/Strin'")
    one_line_error(tf(runtime_dir, "topic", "pub", "/chatter", "String", "{data: x}", *fleet),
                   "PACKAGE/NAME")
    one_line_error(tf(runtime_dir, "service", "call", "/add_two_ints",
                      "example_interfaces/srv/AddTwoInts", "{a: 1, c: 2}", *fleet),
                   "unknown field 'c'")
    one_line_error(tf(runtime_dir, "service", "call", "/add_two_ints",
                      "example_interfaces/srv/AddTwoInts", "{a: 1, b: two}", *fleet),
                   "field 'b' must be integer")
    one_line_error(tf(runtime_dir, "service", "call", "/nothing", "std_msgs/Empty", *fleet),
                   "no server")


def test_debug_shows_the_traceback(runtime_dir, tmp_path):
    result = tf(runtime_dir, "--debug", "bag", "info", str(tmp_path / "none.mcap"))
    assert result.returncode == 2 and "Traceback" in result.stderr
    assert result.stderr.strip().splitlines()[-1].startswith("twinfleet ")
