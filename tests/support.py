"""Helpers shared by every test package that starts processes."""

from __future__ import annotations

import atexit
import os
import re
import shutil
import socket
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# The fleet registry of every process a test starts (twinfleet/runtime/access/registry.py): one private
# directory per test session, so test fleets never mix with a developer's own fleets or with
# another test session's, and a test that finds "the running fleet" finds its own.
RUNTIME_DIR = tempfile.mkdtemp(prefix="twinfleet-test-runtime-")
atexit.register(shutil.rmtree, RUNTIME_DIR, ignore_errors=True)  # the session's, only


def pick_free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def child_env(runtime_dir: str | Path | None = None) -> dict[str, str]:
    """Environment for subprocesses: the project on PYTHONPATH, unbuffered output, no fleet
    inherited from the developer's shell (TWINFLEET_CONNECT / TWINFLEET_FLEET), and the
    session's private fleet registry (or `runtime_dir`'s) as the per-user runtime directory."""
    env = dict(os.environ)
    env["XDG_RUNTIME_DIR"] = str(runtime_dir or RUNTIME_DIR)
    env.pop("TWINFLEET_RUNTIME_DIR", None)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH", "")) if p)
    env["PYTHONUNBUFFERED"] = "1"
    env.pop("TWINFLEET_CONNECT", None)
    env.pop("TWINFLEET_FLEET", None)
    return env


@dataclass
class RunningFleet:
    """A launcher process and where to find it."""

    proc: subprocess.Popen
    log: Path
    scenario: Path
    endpoint: str
    fleet: str

    def output(self) -> str:
        return self.log.read_text(errors="replace")

    def count(self, pattern: str) -> int:
        return len(re.findall(pattern, self.output()))


def wait_for_line(proc: subprocess.Popen[str], text: str) -> None:
    """Read `proc`'s stderr until a line holds `text` (fails the test if it ends first)."""
    import pytest

    assert proc.stderr is not None
    for line in proc.stderr:
        if text in line:
            return
    pytest.fail(f"{text!r} never printed (exit {proc.poll()})")
