"""Helpers of the viewer and recorder tests: ports, child environment, process cleanup,
polling with deadlines, JSON over HTTP."""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import subprocess
import time
import urllib.request
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from tests.support import ROOT, child_env  # noqa: F401 (re-exported)
from tests.support import pick_free_port as free_port  # noqa: F401

ARTIFACTS = ROOT / "out" / "test-artifacts"



def stop_process(proc: subprocess.Popen) -> None:
    """SIGINT, then SIGKILL to the whole process group after a grace period."""
    if proc.poll() is None:
        with contextlib.suppress(ProcessLookupError):
            proc.send_signal(signal.SIGINT)
        with contextlib.suppress(subprocess.TimeoutExpired):
            proc.wait(timeout=8)
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(proc.pid, signal.SIGKILL)
    with contextlib.suppress(subprocess.TimeoutExpired):
        proc.wait(timeout=5)


def poll(predicate: Callable[[], Any], timeout: float, what: str, interval: float = 0.05) -> Any:
    """Poll until `predicate()` is truthy; fail the test naming `what` after `timeout` s."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() >= deadline:
            pytest.fail(f"timed out after {timeout:g} s waiting for {what}")
        time.sleep(interval)


def get_json(url: str) -> Any:
    """GET a JSON document, None if the server does not answer (yet)."""
    try:
        with urllib.request.urlopen(url, timeout=2) as reply:
            return json.load(reply)
    except OSError:
        return None


_PRINTED_URL = re.compile(r"\b(?:http|ws)://127\.0\.0\.1:\d+/\?token=[\w-]+")


def printed_url(log: Path, timeout: float = 20.0) -> str:
    """The URL (with its per-run token) a `view` or `foxglove` server printed into `log`."""
    return poll(lambda: (m := _PRINTED_URL.search(log.read_text(errors="replace"))) and m.group(0),
                timeout, f"the server's URL in {log.name}")


def api(url: str, path: str) -> str:
    """`path` on the server of a printed `url`, with the same token."""
    base, _, query = url.partition("?")
    return f"{base}{path}?{query}"
