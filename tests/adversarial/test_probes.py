"""Hostile input the live fleet withstands, kept so that it goes on doing so:
garbage bytes, deep nesting, bad service requests, kill -9 of a robot or of the launcher,
bad scenario and map files. Each runs against its own fleet on loopback, bounded traffic."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys

import msgpack
import pytest

from tests.adversarial.harness import (
    client,
    envelope,
    launch,
    poll,
    put,
    running_fleet,
    stats,
    stop,
    wait_matched,
    write_scenario,
)
from tests.integration.itest_support import node_pid, spawned_by
from tests.support import ROOT, child_env, pick_free_port
from twinfleet.runtime.core.guard import sign


def _nested(depth: int) -> bytes:
    return b"\x91" * depth + b"\x00"  # a one-element array inside another, `depth` times


def _call(session, fleet: str, payload: bytes, key: bytes | None) -> str:
    where = f"twinfleet/{fleet}/generate_path"
    replies = list(session.get(where, payload=payload, timeout=5.0,
                               attachment=sign(key, where, payload) if key else None))
    assert replies, "no answer"
    reply = replies[0]
    return "ok" if reply.ok is not None else reply.err.payload.to_string()


@pytest.mark.slow
@pytest.mark.timeout(90)
def test_garbage_nesting_bad_requests_then_kill_9_of_a_robot(tmp_path) -> None:
    with running_fleet(tmp_path, "probes", goal=40, scale=1.0) as fleet:
        key = fleet.key
        s = client(fleet.endpoint, fleet.login("operator"))
        try:
            wait_matched(s, fleet.fleet, "/poses")
            for payload in (b"\xc1 garbage", b"", _nested(100_000),
                            msgpack.packb({"type": "x", "data": {"a": [[[[1]]]] * 3}})):
                put(s, fleet.fleet, "/poses", payload, key)  # signed: reaches the decoder
            put(s, fleet.fleet, "/poses", b"\xc1 unsigned garbage")
            counted = poll(lambda: (stats(s, fleet.fleet, "map_server") or {})
                           .get("dropped_undecodable") == 4, 10)
            assert counted, stats(s, fleet.fleet, "map_server")
            assert stats(s, fleet.fleet, "map_server")["rejected_forged"] == 1
            assert "server error" in _call(s, fleet.fleet, b"\xc1", key)
            assert "unauthenticated" in _call(s, fleet.fleet, b"\xc1", None)
            bad = envelope("twinfleet_msgs/PathRequest", {"robot": "r1", "start": [float("nan"), 1],
                                                          "goal": [5, 9]}, sender="r1")
            assert "rejected request" in _call(s, fleet.fleet, bad, key)
            assert stats(s, fleet.fleet, "map_server")["handler_errors"] == 0
        finally:
            s.close()
        pid = int(poll(lambda: _pid_of(fleet.proc.pid, "r1"), 5))
        os.kill(pid, signal.SIGKILL)
        code = fleet.wait_end(30)
        out = fleet.output()
    assert code == 1 and "node r1 failed (exit code -9)" in out, out[-2000:]
    assert not _pid_of(fleet.proc.pid, "r2")


@pytest.mark.slow
@pytest.mark.timeout(60)
def test_kill_9_of_the_launcher_takes_its_nodes_down(tmp_path) -> None:
    scenario = write_scenario(tmp_path, "orphans", goal=40, scale=1.0)
    proc = launch(scenario, tmp_path / "orphans.log", "--listen",
                  f"tcp/127.0.0.1:{pick_free_port()}")
    try:
        assert poll(lambda: _pid_of(proc.pid, "r2"), 30)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
        assert poll(lambda: not any(_pid_of(proc.pid, n) for n in ("map_server", "r1", "r2")), 15)
    finally:
        stop(proc)
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)


@pytest.mark.timeout(60)
@pytest.mark.offline  # refused before any process starts
def test_bad_scenario_and_map_files_end_in_one_line(tmp_path) -> None:
    good = write_scenario(tmp_path, "files").read_text()
    broken_map = tmp_path / "broken.yaml"
    broken_map.write_text("image: nowhere.pgm\nresolution: x\n")
    cases = {"syntax.yaml": "name: [unclosed\n",
             "nomap.yaml": good.replace(f"{ROOT}/twinfleet/maps/map50.yaml", "missing.yaml"),
             "badmap.yaml": good.replace(f"{ROOT}/twinfleet/maps/map50.yaml", str(broken_map)),
             "binary.yaml": None}
    for name, text in cases.items():
        path = tmp_path / name
        if text is None:
            path.write_bytes(b"\xff\xfe\x00garbage")
        else:
            path.write_text(text)
        result = subprocess.run([sys.executable, "-m", "twinfleet", "launch", str(path)],
                                capture_output=True, text=True, timeout=30, env=child_env(),
                                cwd=ROOT, check=False)
        lines = result.stderr.strip().splitlines()
        assert result.returncode == 2 and len(lines) == 1, (name, result.stdout, result.stderr)
        assert str(path) in lines[0] and "Traceback" not in result.stdout, (name, lines)


def _pid_of(launcher: int, node: str) -> int | None:
    """The live process of `node` that this test's `launcher` started (found by pid, never
    by command line: another test's fleet is never a candidate)."""
    return node_pid(spawned_by(launcher), node)
