"""Where Ray's own notices go while a command starts or stops a cluster: into a log file,
not the user's terminal.

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
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


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
