"""Helpers of the integration tests: ports, polling, the processes a test started, CLI subprocesses.

A test ends only what it started: `spawned_by(pid)` follows parent links (and a node's
launcher, named in its environment) from a process the test spawned; nothing here finds
processes by their command line, so a test never ends another test's fleet.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from tests.support import ROOT, child_env, pick_free_port  # noqa: F401 (re-exported)
from twinfleet.runtime.fleet.node_main import PARENT_ENV


def poll(predicate: Callable[[], object], timeout: float, interval: float = 0.05) -> bool:
    """Poll `predicate` until it is truthy or `timeout` seconds pass; return its last truth."""
    deadline = time.monotonic() + timeout
    while True:
        if predicate():
            return True
        if time.monotonic() >= deadline:
            return False
        time.sleep(interval)


def _parent(pid: int) -> int | None:
    """The parent of a live, non-zombie process (None: gone, or a zombie)."""
    try:
        fields = (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None
    return None if fields[0] == "Z" else int(fields[1])


def _launcher_of(pid: int) -> int | None:
    """The launcher a node process names in its environment (None: not a node process)."""
    try:
        environ = (Path("/proc") / str(pid) / "environ").read_bytes().split(b"\0")
    except OSError:
        return None
    key = PARENT_ENV.encode() + b"="
    return next((int(item[len(key):]) for item in environ if item.startswith(key)), None)


def spawned_by(root: int) -> list[int]:
    """Every live process that `root` started, transitively: its descendants, and the node
    processes whose launcher was `root` or one of those (a node outlives a killed launcher;
    tests/conftest.py makes the test process their subreaper, so they stay descendants of
    the test process). Only descendants of the test process are ever considered.
    """
    mine = _mine()
    found: set[int] = set()
    frontier = {root}
    while frontier:
        frontier = {pid for pid, seen in mine.items() if pid not in found | frontier
                    and (seen.parent in frontier or seen.launcher in frontier)}
        found |= frontier
    return sorted(found)


def fleet_nodes() -> list[int]:
    """The live node processes of the fleets this test process launched itself (`run_fleet`
    called in-process); not those of a launcher it started as a subprocess."""
    return sorted(pid for pid, seen in _mine().items() if seen.launcher == os.getpid())


def orphaned_nodes() -> list[int]:
    """Node processes this test process started through a launcher that has ended (a
    launcher run to its end with `subprocess.run` must leave none)."""
    mine = _mine()
    return sorted(pid for pid, seen in mine.items()
                  if seen.launcher not in (None, os.getpid()) and seen.launcher not in mine)


@dataclass(frozen=True)
class _Seen:
    """A process as one scan of /proc saw it: its parent, and the launcher it names (None:
    not a node process)."""

    parent: int | None
    launcher: int | None


def _mine() -> dict[int, _Seen]:
    """The live descendants of this test process, by pid: the one scan of /proc that
    `spawned_by`, `fleet_nodes` and `orphaned_nodes` read."""
    parents = {pid: _parent(pid) for pid in _pids()}
    return {pid: _Seen(parents[pid], _launcher_of(pid))
            for pid in _descendants(parents, os.getpid())}


def _pids() -> list[int]:
    return [int(entry.name) for entry in Path("/proc").iterdir() if entry.name.isdigit()]


def _descendants(parents: dict[int, int | None], root: int) -> set[int]:
    found: set[int] = set()
    frontier = {root}
    while frontier:
        frontier = {pid for pid, parent in parents.items() if parent in frontier} - found
        found |= frontier
    return found


def node_pid(pids: list[int], node: str) -> int | None:
    """The node process running `node` among `pids` (processes the test started, from
    `spawned_by` or `fleet_nodes`), or None."""
    for pid in pids:
        try:
            argv = (Path("/proc") / str(pid) / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if b"--node" in argv[:-1] and argv[argv.index(b"--node") + 1] == node.encode():
            return pid
    return None


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


def stop_launch(proc: subprocess.Popen) -> None:
    """SIGINT a launcher, SIGKILL it after 15 s, then kill what it started and left behind."""
    started = spawned_by(proc.pid)
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=5)
    kill_all(sorted(set(started) | set(spawned_by(proc.pid))))
