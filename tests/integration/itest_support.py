"""Helpers of the integration tests: ports, polling, /proc scans, CLI subprocesses."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

from tests.support import ROOT, child_env, pick_free_port  # noqa: F401 (re-exported)


def poll(predicate: Callable[[], object], timeout: float, interval: float = 0.05) -> bool:
    """Poll `predicate` until it is truthy or `timeout` seconds pass; return its last truth."""
    deadline = time.monotonic() + timeout
    while True:
        if predicate():
            return True
        if time.monotonic() >= deadline:
            return False
        time.sleep(interval)


def processes_mentioning(text: str) -> list[int]:
    """PIDs of live processes whose command line contains `text` (a /proc scan, no psutil)."""
    pids = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            cmdline = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            state = (entry / "stat").read_text().split(")")[-1].split()[0]
        except OSError:
            continue
        if text in cmdline and state != "Z":
            pids.append(int(entry.name))
    return pids


def kill_all(pids: list[int]) -> None:
    """SIGKILL every pid (cleanup of last resort)."""
    for pid in pids:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)




def run_cli(*args: str, timeout: float = 20.0) -> subprocess.CompletedProcess[str]:
    """Run `python -m twinfleet ARGS` and capture its output."""
    return subprocess.run([sys.executable, "-m", "twinfleet", *args], capture_output=True,
                          text=True, timeout=timeout, env=child_env(), cwd=ROOT, check=False)


def run_cli_in(runtime_dir: Path, *args: str, timeout: float = 30.0
               ) -> subprocess.CompletedProcess[str]:
    """`python -m twinfleet ARGS` with the fleet registry of `runtime_dir` (its
    XDG_RUNTIME_DIR) and no connection options or variables."""
    return subprocess.run([sys.executable, "-m", "twinfleet", *args], capture_output=True,
                          text=True, timeout=timeout, env=child_env(runtime_dir), cwd=ROOT,
                          check=False)


def launch_in(runtime_dir: Path, log: Path, *args: str) -> subprocess.Popen:
    """Start `twinfleet launch ARGS` with the fleet registry of `runtime_dir`, output to `log`."""
    with log.open("w") as sink:
        return subprocess.Popen([sys.executable, "-m", "twinfleet", "launch", *args],
                                stdout=sink, stderr=subprocess.STDOUT, env=child_env(runtime_dir),
                                cwd=ROOT, start_new_session=True)


def stop_launch(proc: subprocess.Popen, scenario: str) -> None:
    """SIGINT a launcher, SIGKILL it after 15 s, then kill node processes it left behind."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=5)
    kill_all([p for p in processes_mentioning(scenario) if p != proc.pid])


def node_pid(scenario: Path | str, node: str) -> int | None:
    """PID of the live node process running `node` of `scenario` (a /proc scan)."""
    for pid in processes_mentioning(str(scenario)):
        try:
            argv = (Path("/proc") / str(pid) / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if b"twinfleet.runtime.fleet.node_main" in argv and argv[argv.index(b"--node") + 1] == node.encode():
            return pid
    return None
