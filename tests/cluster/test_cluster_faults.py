"""The distributed search on a simulated two-machine cluster, and when the cluster fails.

`ray.cluster_utils.Cluster` runs two Ray nodes on this machine (one CPU each, so
the two workers land one per node); the answers are the single process's. A
shard killed mid-search ends `twinfleet check --workers 2` with exit 2 and one
line, never a verdict; a bad `--cluster` address is one line, exit 2.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.cluster.test_distributed import assert_same_answer, safety_copy
from tests.integration.itest_support import spawned_by
from tests.support import child_env
from twinfleet.checker import CheckOptions, check
from twinfleet.checker.cluster import engine_module

pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]

ROOT = Path(__file__).resolve().parents[2]


def test_two_nodes_give_the_single_process_answer(tmp_path: Path) -> None:
    engine_module()  # Ray imported with the local cluster's settings (loopback)
    import ray
    from ray.cluster_utils import Cluster

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1})
    try:
        cluster.add_node(num_cpus=1)
        ray.init(address=cluster.address, log_to_driver=False, configure_logging=False,
                 runtime_env={"env_vars": {"PYTHONPATH": str(ROOT)}})
        assert len([n for n in ray.nodes() if n["Alive"]]) == 2
        path = safety_copy("headon", tmp_path, latency={"default": [0, 1]})
        one = check(path, CheckOptions(reduction="none", max_depth=40))
        many = check(path, CheckOptions(reduction="none", workers=2, cluster=cluster.address,
                                        min_width=1, max_depth=40))
        assert (many.engine or "").startswith("strict BFS on 2 Ray worker(s)"), many.engine
        assert_same_answer(one, many)
    finally:
        ray.shutdown()
        cluster.shutdown()


def _pid_named(prefix: bytes, root: int) -> int | None:
    """A process `root` started (its local cluster's, in a session of its own) whose
    command line starts with `prefix`."""
    for pid in spawned_by(root):
        with contextlib.suppress(OSError):
            if Path(f"/proc/{pid}/cmdline").read_bytes().startswith(prefix):
                return pid
    return None


@pytest.mark.parametrize(("order", "victim"), [(["--search", "bfs"], b"ray::Shard"),
                                               ([], b"ray::FlowWorker")])
def test_a_shard_killed_mid_search_ends_with_no_verdict(tmp_path: Path, order: list[str],
                                                        victim: bytes) -> None:
    # strict BFS: a shard actor; relaxed order: a worker, which holds a partition too
    path = safety_copy("c2c", tmp_path)
    proc = subprocess.Popen([sys.executable, "-m", "twinfleet", "check", str(path),
                             "--reduction", "none", "--workers", "2", "--min-width", "1",
                             *order],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=child_env(), cwd=ROOT, start_new_session=True)
    try:
        assert proc.stderr is not None
        for line in proc.stderr:
            if "starting 2 Ray worker(s)" in line:
                break
        deadline = time.monotonic() + 60
        shard = None
        while shard is None and time.monotonic() < deadline and proc.poll() is None:
            shard = _pid_named(victim, proc.pid)
            time.sleep(0.05)
        assert shard is not None, "no shard actor process appeared"
        os.kill(shard, signal.SIGKILL)
        out, err = proc.communicate(timeout=120)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 2, (out, err)
    assert "no verdict" in err.strip().splitlines()[-1], err
    assert "verdict:" not in out and "HOLDS" not in out and "VIOLATED" not in out, out


def test_a_bad_cluster_address_is_one_line(tmp_path: Path) -> None:
    path = safety_copy("headon", tmp_path)
    result = subprocess.run([sys.executable, "-m", "twinfleet", "check", str(path),
                             "--reduction", "none", "--cluster", "127.0.0.1:1", "--min-width",
                             "1"], capture_output=True, text=True, env=child_env(), cwd=ROOT,
                            timeout=120, check=False)
    assert result.returncode == 2, result
    lines = result.stderr.strip().splitlines()
    assert lines[-1].startswith("twinfleet check: cannot connect to cluster 127.0.0.1:1"), lines
    assert "Traceback" not in result.stderr

