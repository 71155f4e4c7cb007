"""Every environment variable twinfleet reads, named once.

A variable is read through `env_value` with its `EnvVar`; no other module reads
`os.environ` for a value (tests/test_environment.py checks it, and that
docs/environment.md describes every member). The launcher sets some of them for its node
processes (secrets, its pid, limits); others are a user's defaults for command-line options.
The few variables of other programs that twinfleet reads are listed here too, so that one
place answers "what in my environment changes what twinfleet does".
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from enum import StrEnum


class EnvVar(StrEnum):
    """An environment variable that twinfleet reads (the value is its name)."""

    # a user's defaults for command-line options
    CONNECT = "TWINFLEET_CONNECT"
    FLEET = "TWINFLEET_FLEET"
    CREDENTIALS = "TWINFLEET_CREDENTIALS"
    RUNTIME_DIR = "TWINFLEET_RUNTIME_DIR"
    ZENOH_CONFIG_OVERRIDE = "TWINFLEET_ZENOH_CONFIG_OVERRIDE"
    # set by the launcher for its node processes
    LAUNCHER_PID = "TWINFLEET_LAUNCHER_PID"
    MAX_PAYLOAD = "TWINFLEET_MAX_PAYLOAD"
    FLEET_KEY = "TWINFLEET_FLEET_KEY"
    BRIDGE_KEY = "TWINFLEET_BRIDGE_KEY"
    ZENOH_USER = "TWINFLEET_ZENOH_USER"
    ZENOH_PASSWORD = "TWINFLEET_ZENOH_PASSWORD"
    TLS_CA = "TWINFLEET_TLS_CA"
    ACCEPT_RECORDED = "TWINFLEET_ACCEPT_RECORDED"
    # other programs' variables that twinfleet reads
    XDG_RUNTIME_DIR = "XDG_RUNTIME_DIR"
    PYTHONPATH = "PYTHONPATH"
    RAY_WORKER_NICENESS = "RAY_worker_niceness"
    AMENT_PREFIX_PATH = "AMENT_PREFIX_PATH"


def env_value(var: EnvVar, env: Mapping[str, str] | None = None) -> str | None:
    """The value of `var` in `env` (default: this process's environment), or None."""
    return (os.environ if env is None else env).get(var.value)
