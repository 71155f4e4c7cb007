"""What a Ray session needs of this process, none of it Ray itself: the environment its
workers inherit (`worker_env`, `environment`), the check that a cluster's address answers
(`answers`), and where Ray's own notices go while a command starts or stops a cluster:
into a log file, not the user's terminal (`ray_notices`).

Ray speaks in two ways. Its Python side logs through ``ray.*`` loggers, whose ``ray``
logger Ray gives a handler on stderr when imported (``configure_logging=False`` does not
remove it); its C++ core (the driver's and the processes ``ray.init`` starts, which
inherit this process's stderr) writes to file descriptor 2 directly — a local cluster's
"Token authentication is enabled for this Ray cluster..." among them. `ray_notices`
points both at one file (`ray_log_path`, appended to) while a block runs, so the
processes started in it keep writing there, and puts stderr and the logger back after.
"""

from __future__ import annotations

import logging
import os
import socket
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from twinfleet.checker.cluster.spec import ClusterError
from twinfleet.runtime.contract.environment import EnvVar, env_value


def ray_log_path() -> Path:
    """The file Ray's notices go to: ``<temp dir>/twinfleet-ray-<uid>.log``."""
    return Path(tempfile.gettempdir()) / f"twinfleet-ray-{os.getuid()}.log"


@contextmanager
def ray_notices() -> Iterator[Path]:
    """Send Ray's notices to `ray_log_path` while the block runs (module docstring)."""
    path = ray_log_path()
    logger = logging.getLogger("ray")
    handler = logging.FileHandler(path, encoding="utf-8", delay=True)
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    saved = logger.handlers[:], logger.propagate
    logger.handlers = [handler]
    logger.propagate = False
    sys.stderr.flush()
    stderr = os.dup(2)
    log = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o600)
    os.dup2(log, 2)
    try:
        yield path
    finally:
        sys.stderr.flush()
        os.dup2(stderr, 2)
        os.close(stderr)
        os.close(log)
        logger.handlers, logger.propagate = saved
        handler.close()

def worker_env() -> dict[str, str]:
    """Workers import node code as this process does: its working directory and path."""
    path = [os.getcwd(), *filter(None, (env_value(EnvVar.PYTHONPATH) or "").split(os.pathsep))]
    return {"PYTHONPATH": os.pathsep.join(path), "RAY_USAGE_STATS_ENABLED": "0"}


@contextmanager
def environment(values: dict[str, str]) -> Iterator[None]:
    """`values` in this process's environment while the block runs, the old ones back
    after."""
    before = {name: os.environ.get(name) for name in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for name, value in before.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def answers(address: str) -> None:
    """ClusterError unless something accepts a connection at `address` (HOST:PORT): Ray
    itself keeps retrying an address where nothing listens."""
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit():
        raise ClusterError(f"--cluster {address}: expected HOST:PORT, the address "
                           "`ray start --head` prints")
    try:
        socket.create_connection((host, int(port)), timeout=5).close()
    except OSError as exc:
        raise ClusterError(f"cannot connect to cluster {address}: "
                           f"{exc.strerror or exc}") from None
