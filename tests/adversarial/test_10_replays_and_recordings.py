"""Signed is not enough: a replayed sample and an unsigned `play` are dropped and counted,
and recorded input reaches a fleet only on purpose (`play --into-fleet` into a fleet
launched with --accept-recorded), which the run's result then says."""

from __future__ import annotations

import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.adversarial.fleets import launch_command
from tests.adversarial.harness import client, poll, running_fleet, stats, stop
from tests.integration.itest_support import kill_all, spawned_by
from tests.support import ROOT, child_env, pick_free_port
from twinfleet.runtime.contract.messages import String, encode
from twinfleet.runtime.tools.record.recorder import McapRecorder

pytestmark = [pytest.mark.slow, pytest.mark.timeout(120)]

LISTENER = '''
from twinfleet import Context, Node, subscribe
from twinfleet.runtime.contract.messages import String


class Listener(Node):
    """Logs every /note it is given."""

    @subscribe("/note")
    def on_note(self, ctx: Context, msg: String) -> None:
        ctx.log("heard", data=msg.data)
'''
NOTES = 5


def test_a_replayed_signed_sample_is_dropped_and_counted(tmp_path) -> None:
    with running_fleet(tmp_path, "replay", goal=30, scale=1.0) as fleet:
        heard: list[tuple[str, bytes, bytes]] = []
        monitor = client(fleet.endpoint, fleet.login("monitor"))
        operator = client(fleet.endpoint, fleet.login("operator"))
        try:
            sub = monitor.declare_subscriber(
                f"twinfleet/{fleet.fleet}/poses",
                lambda s: heard.append((str(s.key_expr), s.payload.to_bytes(),
                                        s.attachment.to_bytes())))
            assert poll(lambda: len(heard) >= 6, 20), "no signed poses heard"
            sub.undeclare()
            before = stats(operator, fleet.fleet, "map_server")
            assert before is not None
            for key, payload, attachment in heard[:6]:  # an insider sends them again
                operator.put(key, payload, attachment=attachment)
            after = poll(lambda: (s := stats(operator, fleet.fleet, "map_server"))
                         and s["rejected_replayed"] >= before["rejected_replayed"] + 6 and s, 10)
            assert after, stats(operator, fleet.fleet, "map_server")
            assert after["rejected_forged"] == before["rejected_forged"]  # signed: not forged
        finally:
            monitor.close()
            operator.close()
        stop(fleet.proc)
        out = fleet.output()
    assert re.search(r"^\[map_server\] stopped: .* rejected_replayed=6\b", out, re.M), out
    assert "refused samples on the report and shutdown topics: replayed 6" in out, out


def _recording(path: Path) -> Path:
    recorder = McapRecorder(path.open("wb"))
    for i in range(NOTES):
        recorder.write("twinfleet/recorded/note",
                       encode(String(f"recorded {i}"), seq=i + 1, sender="talker"))
    recorder.close()
    return path


def _play(recording: Path, endpoint: str, fleet: str, *args: str) -> str:
    done = subprocess.run([sys.executable, "-m", "twinfleet", "play", str(recording),
                           "--connect", endpoint, "--fleet", fleet, "--wait", "10", *args],
                          capture_output=True, text=True, timeout=60, env=child_env(), cwd=ROOT,
                          check=False)
    assert done.returncode == 0, done.stdout + done.stderr
    return done.stdout


@pytest.mark.parametrize("accept", [False, True])
def test_recorded_input_reaches_a_fleet_only_on_purpose(tmp_path, accept) -> None:
    (tmp_path / "listening.py").write_text(LISTENER)
    scenario = tmp_path / "notes.yaml"
    scenario.write_text('name: notes\nnodes:\n  - {name: ear, class: "listening:Listener"}\n')
    recording = _recording(tmp_path / "notes.mcap")
    endpoint = f"tcp/127.0.0.1:{pick_free_port()}"
    log = tmp_path / "launch.log"
    flags = ["--listen", endpoint, "--timeout", "30", "-v",
             *(["--accept-recorded"] if accept else [])]
    with log.open("w") as sink:
        proc = subprocess.Popen(launch_command(scenario, *flags), stdout=sink,
                                stderr=subprocess.STDOUT, env=child_env(), cwd=ROOT,
                                start_new_session=True)
    try:
        assert poll(lambda: "[ear] t=" in log.read_text() and "started" in log.read_text(),
                    30), log.read_text()
        unsigned = _play(recording, endpoint, "notes")  # play as it always was: not signed
        assert f"played {NOTES} messages" in unsigned
        into = _play(recording, endpoint, "notes", "--into-fleet")
        assert "signed as recorded input" in into and f"played {NOTES} messages" in into
        time.sleep(0.5)
    finally:
        stop(proc)
        kill_all(spawned_by(proc.pid))
    out = log.read_text()
    counters = re.search(r"^\[ear\] stopped: (.*)$", out, re.M)
    assert counters, out
    values = dict(word.split("=") for word in counters.group(1).split())
    assert values["rejected_forged"] == str(NOTES), out  # the unsigned play
    heard = out.count("heard data='recorded")
    if accept:
        assert (values["played"], values["rejected_recorded"], heard) == (str(NOTES), "0", NOTES)
        assert "ear: 5 recorded samples from twinfleet play --into-fleet" in out
    else:
        assert (values["played"], values["rejected_recorded"], heard) == ("0", str(NOTES), 0)
        assert "took external input" not in out
