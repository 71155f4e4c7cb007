"""Failure 6: recordings died with the recorder.

Before: kill -9 of `twinfleet record` 4.5 s into a run left a 0-byte MCAP (the
whole recording was held in memory until close); recording onto a nearly full
disk ran to the end, then failed, leaving an unreadable file. Now chunks reach
the file at least twice a second: after kill -9 the mcap reader reads every
message up to the last chunk and `twinfleet bag repair` makes the file complete;
a write that fails with ENOSPC stops the recording at once with one line, and
the file is readable after `bag repair`.
"""

from __future__ import annotations

import contextlib
import errno
import io
import os
import signal
import subprocess
import sys

import pytest
from mcap.reader import NonSeekingReader, make_reader

from tests.adversarial.harness import poll, stop, write_scenario
from tests.support import ROOT, child_env
from twinfleet.runtime.tools.record.bag import read_summary, repair
from twinfleet.runtime.tools.record.recorder import McapRecorder


def _messages(path) -> int:
    count = 0
    with open(path, "rb") as f:
        try:
            for _ in NonSeekingReader(f).iter_messages(log_time_order=False):
                count += 1
        except Exception:  # the reader stops at the cut
            pass
    return count


@pytest.mark.slow
@pytest.mark.timeout(90)
def test_kill_9_of_the_recorder_leaves_every_chunk_readable(tmp_path) -> None:
    scenario = write_scenario(tmp_path, "rec", goal=40, scale=1.0)
    out = tmp_path / "run.mcap"
    proc = subprocess.Popen([sys.executable, "-m", "twinfleet", "record", str(scenario), "-o",
                             str(out)], stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT,
                            env=child_env(), cwd=ROOT, start_new_session=True)
    try:
        assert poll(lambda: out.exists() and _messages(out) > 50, 30), "no chunk reached the file"
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        stop(proc)
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
    kept = _messages(out)
    assert kept > 50
    fixed = subprocess.run([sys.executable, "-m", "twinfleet", "bag", "repair", str(out)],
                           capture_output=True, text=True, env=child_env(), cwd=ROOT,
                           timeout=30, check=False)
    assert fixed.returncode == 0 and f"{kept} messages" in fixed.stdout, fixed.stdout + fixed.stderr
    with open(out, "rb") as f:
        assert sum(1 for _ in make_reader(f).iter_messages()) == kept
    assert read_summary(out).messages == kept


class FillingDisk(io.FileIO):
    """A file that takes `room` bytes and then fails as a full disk does."""

    def __init__(self, path, room: int) -> None:
        super().__init__(path, "w+")
        self.room = room

    def write(self, data) -> int:
        if self.tell() + len(data) > self.room:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return super().write(data)


@pytest.mark.timeout(30)
def test_a_full_disk_stops_the_recording_at_once_with_a_readable_file(tmp_path) -> None:
    path = tmp_path / "full.mcap"
    stopped: list[str] = []
    rec = McapRecorder(FillingDisk(path, 40_000), on_failure=stopped.append)
    rec.metadata({"fleet": "full"})
    payload = os.urandom(300)  # incompressible: the disk fills after ~130 messages
    for i in range(2000):
        rec.write("twinfleet/full/poses", payload)
        if i % 20 == 19:
            rec.flush()
    rec.close()
    assert len(stopped) == 1 and rec.failed == stopped[0]
    assert "No space left on device" in stopped[0] and "bag repair" in stopped[0]
    assert "\n" not in stopped[0]
    assert 0 < rec.messages < 2000
    assert path.stat().st_size <= 40_000
    count, _ = repair(path)
    assert 0 < count <= rec.messages and count % 20 == 0  # every complete chunk, no torn one
    assert read_summary(path).messages == count
