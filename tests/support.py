"""Helpers shared by every test package that starts processes."""

from __future__ import annotations

import os
import socket
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def pick_free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def child_env() -> dict[str, str]:
    """Environment for subprocesses: the project on PYTHONPATH, unbuffered output, and no
    fleet inherited from the developer's shell (TWINFLEET_CONNECT / TWINFLEET_FLEET)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH", "")) if p)
    env["PYTHONUNBUFFERED"] = "1"
    env.pop("TWINFLEET_CONNECT", None)
    env.pop("TWINFLEET_FLEET", None)
    return env
