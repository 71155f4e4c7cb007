"""What `twinfleet check` sets up before it searches: one OpenBLAS thread unless told, and
none of the modules only other commands or a user's own message types need."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.support import child_env

pytestmark = [pytest.mark.timeout(120),
              pytest.mark.skipif(not Path("/proc/self/task").is_dir(),
                                 reason="counts threads in /proc (Linux)")]

# the fleet's credentials (`connection`'s), the ROS 2 definitions a user's type is checked
# against (`interfaces.guard`), the paper's figures and the experiment's table (`robots`)
UNWANTED = ("twinfleet.runtime.access.connection", "twinfleet.runtime.access.fleetauth",
            "twinfleet.interfaces.definitions", "twinfleet.robots.paper",
            "twinfleet.robots.table")
# the threads of the command's process once its check is done (numpy imported by then)
_THREADS = ("import os, sys\nfrom twinfleet.cli import main\n"
            "code = main(['check', sys.argv[1], '--quiet'])\n"
            "print('threads', len(os.listdir('/proc/self/task')), 'exit', code)\n"
            f"print(sorted(set({UNWANTED!r}) & set(sys.modules)))\n")


def _threads(path: Path, blas: str | None) -> str:
    env = child_env()
    env.pop("OPENBLAS_NUM_THREADS", None)
    if blas is not None:
        env["OPENBLAS_NUM_THREADS"] = blas
    done = subprocess.run([sys.executable, "-c", _THREADS, str(path)], env=env, timeout=100,
                          capture_output=True, text=True, check=True)
    return " ".join(done.stdout.splitlines()[-2:])


def test_check_runs_numpy_on_one_blas_thread_unless_the_user_sets_it(tmp_path):
    ok = tmp_path / "ok.yaml"  # twinfleet's own message types only
    ok.write_text("name: ok\nnodes:\n  - {name: listener, class: 'twinfleet.nodes.demo:Listener'}"
                  "\n  - {name: adder, class: 'twinfleet.nodes.demo:Adder'}\n")
    # OpenBLAS' threads busy-wait after numpy's import: a search has no use for them
    assert _threads(ok, None) == "threads 1 exit 0 []"
    if (os.cpu_count() or 1) > 1:  # OpenBLAS starts no thread of its own on one core
        assert _threads(ok, "2") == "threads 2 exit 0 []"
