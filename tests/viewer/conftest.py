"""Fixtures of the viewer and recorder tests: CLI subprocesses that are always cleaned up."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from viewer_support import ROOT, child_env, stop_process

_LOG_TAIL = 25


@pytest.fixture
def cli(tmp_path: Path) -> Iterator[Callable[..., subprocess.Popen]]:
    """Start `python -m twinfleet ARGS` in its own process group, output to tmp_path/LOG;
    every one is stopped (SIGINT, then SIGKILL of its group) at teardown, whatever happened,
    and the end of its log printed (pytest shows it when the test failed)."""
    started: list[subprocess.Popen] = []

    def start(*args: str, log: str) -> subprocess.Popen:
        path = tmp_path / log
        with path.open("w") as sink:
            proc = subprocess.Popen([sys.executable, "-m", "twinfleet", *args], stdout=sink,
                                    stderr=subprocess.STDOUT, env=child_env(), cwd=ROOT,
                                    start_new_session=True)
        proc.log = path  # type: ignore[attr-defined]
        started.append(proc)
        return proc

    yield start
    for proc in reversed(started):
        stop_process(proc)
    for proc in started:
        lines = proc.log.read_text(errors="replace").splitlines()  # type: ignore[attr-defined]
        print(f"--- {' '.join(proc.args[3:])} (exit {proc.returncode}), last lines:",
              *lines[-_LOG_TAIL:], sep="\n")
