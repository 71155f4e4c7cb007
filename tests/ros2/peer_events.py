"""A ROS 2 peer process (zenoh-ros2-sdk in tests/ros2/sdk_*peer.py): started, its JSON events read
on a thread and waited for by kind, stopped."""

from __future__ import annotations

import contextlib
import json
import os
import queue
import subprocess
import sys
import threading
import time
from pathlib import Path


def read_events(proc: subprocess.Popen, out: queue.Queue) -> threading.Thread:
    """Put each JSON line the peer prints into `out`, on a daemon thread (started)."""
    def pump() -> None:
        for line in proc.stdout:
            if line.startswith("{"):
                out.put(json.loads(line))

    thread = threading.Thread(target=pump, daemon=True)
    thread.start()
    return thread


def wait_event(events: queue.Queue, kind: str, timeout: float = 20.0) -> dict:
    """The next event of `kind` (others are dropped); AssertionError after `timeout` s."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            event = events.get(timeout=max(0.01, end - time.monotonic()))
        except queue.Empty:
            break
        if event["event"] == kind:
            return event
    raise AssertionError(f"no {kind} event from the peer")


def start_peer(script: str, port: int, *args: str) -> subprocess.Popen:
    """Run the peer `script` (a file of tests/ros2/) against the router on `port`."""
    env = dict(os.environ, ZENOH_CONFIG_OVERRIDE="scouting/multicast/enabled=false")
    return subprocess.Popen([sys.executable, str(Path(__file__).with_name(script)), str(port),
                             *args],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)


def stop_peer(proc: subprocess.Popen | None) -> None:
    """Ask the peer to quit; kill it if it has not in 10 s."""
    if proc is None:
        return
    with contextlib.suppress(Exception):
        proc.stdin.write("quit\n")
        proc.stdin.flush()
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
