"""What `twinfleet check` sets up before it searches: one OpenBLAS thread unless told."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.checker.helpers import node, scenario
from tests.support import child_env

pytestmark = [pytest.mark.timeout(120),
              pytest.mark.skipif(not Path("/proc/self/task").is_dir(),
                                 reason="counts threads in /proc (Linux)")]

# the threads of the command's process once its check is done (numpy imported by then)
_THREADS = ("import os, sys\nfrom twinfleet.cli import main\n"
            "code = main(['check', sys.argv[1], '--quiet'])\n"
            "print('threads', len(os.listdir('/proc/self/task')), 'exit', code)\n")


def _threads(path: Path, blas: str | None) -> str:
    env = child_env()
    env.pop("OPENBLAS_NUM_THREADS", None)
    if blas is not None:
        env["OPENBLAS_NUM_THREADS"] = blas
    done = subprocess.run([sys.executable, "-c", _THREADS, str(path)], env=env, timeout=100,
                          capture_output=True, text=True, check=True)
    return done.stdout.splitlines()[-1]


def test_check_runs_numpy_on_one_blas_thread_unless_the_user_sets_it(tmp_path):
    ok = scenario(tmp_path, [node("ping", "Ping"), node("pong", "Pong")], name="ok")
    # OpenBLAS' threads busy-wait after numpy's import: a search has no use for them
    assert _threads(ok, None) == "threads 1 exit 0"
    if (os.cpu_count() or 1) > 1:  # OpenBLAS starts no thread of its own on one core
        assert _threads(ok, "2") == "threads 2 exit 0"
