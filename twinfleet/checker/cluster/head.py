"""A local Ray cluster in processes of its own, started without importing Ray here.

`LocalHead` runs Ray's own `ray start --head --block` as a child process, in a
session of its own (a Ctrl-C at the terminal reaches the search, which stops
between two levels, not the cluster under it) and bound to this process's
life: it receives SIGTERM when this process ends, however it ends, and then
stops every process of the cluster. Starting takes seconds of Ray's time (and
of this machine's cores), none of them on the search's thread: the caller
connects once `up` says the cluster answers (`checker.cluster.engine.connect`).

The cluster listens on 127.0.0.1 only, with ports picked free here, no
dashboard and no usage report. Its authentication token is made here, one per
process (Ray caches the token a process first read), and given to the
cluster and to this process's connection through the environment: nothing is
written to ~/.ray and Ray prints no notice about it. Everything Ray says goes
to a log file in the cluster's temporary directory, which is removed after a
clean stop and kept, and named in the error, when the cluster failed.

While the search goes on in this process, the cluster may start in the background
(`Background`): its session's scheduling group (Linux's autogroup, one per session)
gets the lowest priority, so its processes take the cores the search leaves idle
and little of the search's own; `restore` puts it back, once the workers take
the search over or `YIELD_S` after the start at the latest (a cluster starved for
minutes on a busy machine fails on Ray's own timeouts).
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from typing import final

from twinfleet.checker.cluster.ray_host import worker_env
from twinfleet.checker.cluster.spec import ClusterError
from twinfleet.runtime.contract.environment import EnvVar, env_value

TOKEN = secrets.token_hex(32)
STOP_TIMEOUT_S = 15.0
# On SIGTERM `ray start` first drains its node (for Ray Serve), up to 30 s: 0.5-3.4 s
# measured here with nothing to drain; a search's workers have nothing worth waiting for.
QUICK_STOP = {"RAY_GRACEFUL_SHUTDOWN_DRAIN_TIMEOUT_S": "0"}
STARTED = b"Ray runtime started."  # what `ray start` logs once the cluster is up
PR_SET_PDEATHSIG = 1  # prctl(2): a signal for the child when its parent thread ends
# The niceness of a cluster starting beside the search: a weight of 15 against the search's
# 1,024 (sched(7)); any user may set their own session's group to 0..19.
BACKGROUND_NICENESS = 19
# At most this long in the background: Ray's processes gave up (GCS connection timed out)
# after 2.5 minutes starved at load 7 on this 2-core machine; up in 5-20 s at normal priority.
YIELD_S = 20.0
AUTOGROUP_RATE_S = 0.1  # sched(7): a user's autogroup niceness changes at most this often


def free_port() -> int:
    """A TCP port free on 127.0.0.1 now."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def _die_with_parent() -> None:  # pragma: no cover - runs in the child, between fork and exec
    """SIGTERM to the child when the thread that started it ends (Linux; elsewhere a
    killed command leaves its cluster to Ray's own reaper)."""
    if sys.platform.startswith("linux"):
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)


def _group_niceness(pid: int, niceness: int) -> None:
    """Set the niceness of the scheduling group (autogroup) of `pid`'s session; nothing
    where the kernel has no autogroups (then the cluster runs at normal priority) or the
    session ended. The kernel takes one change a tenth of a second from a user: a second
    change sooner is retried."""
    for _ in range(3):
        try:
            with open(f"/proc/{pid}/autogroup", "w") as group:
                group.write(str(niceness))
        except OSError as exc:
            if exc.errno == errno.EAGAIN:
                time.sleep(AUTOGROUP_RATE_S)
                continue
        return


@final
class Background:
    """The priority of the session led by `pid` (a cluster's processes): `lower` for at
    most some seconds, `restore` (module docstring)."""

    def __init__(self, pid: int) -> None:
        self.pid = pid
        self._deadline: threading.Timer | None = None

    def lower(self, at_most_s: float = YIELD_S) -> None:
        """The lowest priority, for `at_most_s` seconds at most or until `restore`."""
        _group_niceness(self.pid, BACKGROUND_NICENESS)
        self._deadline = threading.Timer(at_most_s, self.restore)
        self._deadline.daemon = True
        self._deadline.start()

    def restore(self) -> None:
        """Normal priority again (after `lower`; once)."""
        deadline, self._deadline = self._deadline, None
        if deadline is not None:
            deadline.cancel()
            _group_niceness(self.pid, 0)

    def cancel(self) -> None:
        """Forget the deadline (the session ends)."""
        if self._deadline is not None:
            self._deadline.cancel()


def driver_env() -> dict[str, str]:
    """What a process connecting to a `LocalHead` needs in its environment before it
    imports Ray: the cluster switch off (Ray reads it once, at import: on, a local
    cluster listens on every interface), no usage report, the token."""
    return {"RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0", "RAY_USAGE_STATS_ENABLED": "0",
            "RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": TOKEN}


@final
class LocalHead:
    """A local Ray cluster of `cpus` CPUs, started at construction (module docstring).

    Must be constructed on the thread that lives as long as the cluster should (the
    main thread): the cluster stops when that thread ends.

    Args:
        cpus: the cluster's CPUs (one per worker actor).
        env: the environment of the cluster's processes, which Ray's workers inherit
            (the node code's import path, their niceness), over this process's.
    """

    def __init__(self, cpus: int, env: dict[str, str]) -> None:
        self.directory = tempfile.mkdtemp(prefix="twinfleet-ray-")
        self.log = os.path.join(self.directory, "ray.log")
        self.driver_log = os.path.join(self.directory, "driver.log")  # this process's Ray
        self.address = f"127.0.0.1:{free_port()}"
        self._failed = False
        self._up = False  # `ray start` said the cluster is up
        self._stopping = False  # `stop` was called: the process's end is no failure
        command = [sys.executable, "-m", "ray.scripts.scripts", "start", "--head", "--block",
                   "--port", self.address.rsplit(":", 1)[1], "--node-ip-address", "127.0.0.1",
                   "--num-cpus", str(cpus), "--include-dashboard", "false",
                   "--disable-usage-stats", "--temp-dir", self.directory,
                   # The autoscaler's monitor serves no fixed local cluster: 80 MB.
                   "--no-monitor",
                   # Ray's defaults are fixed ports (10001, 52365): two clusters on one
                   # machine would collide on them.
                   "--ray-client-server-port", str(free_port()),
                   "--dashboard-agent-listen-port", str(free_port())]
        with open(self.log, "wb") as out:
            self.process = subprocess.Popen(  # noqa: S603 - our own interpreter, fixed arguments
                command, env={**os.environ, **env, **driver_env(), **QUICK_STOP}, stdin=subprocess.DEVNULL,
                stdout=out, stderr=subprocess.STDOUT, start_new_session=True,
                preexec_fn=_die_with_parent)  # noqa: PLW1509 - started from the main thread
        self.background = Background(self.process.pid)  # its session's priority

    def up(self) -> bool:
        """Whether `ray start` has started every process of the cluster (it says so in its
        log); ClusterError when it stopped. Joining earlier would wait inside Ray for the
        rest, where an end of the command could no longer cut it short: Ray ends a
        process whose cluster stopped while it was joining."""
        if self.process.poll() is not None:
            raise ClusterError(self.failure())
        try:
            with open(self.log, "rb") as said:
                self._up = STARTED in said.read()
        except OSError:
            return False
        return self._up

    def wait_up(self, poll_s: float = 0.05) -> None:
        """Return once the cluster answers; ClusterError when it stopped first."""
        while not self.up():
            time.sleep(poll_s)

    def failure(self) -> str:
        """The one-line error of a cluster that failed, naming the log (which is kept)."""
        self._failed = not self._stopping
        last = ""
        with contextlib.suppress(OSError), open(self.log, errors="replace") as lines:
            last = next((line.strip() for line in reversed(lines.readlines()) if line.strip()),
                        "")
        code = self.process.poll()
        how = "failed" if code is None else f"stopped (exit {code})"
        return (f"the local Ray cluster {how}" + (f": {last[:200]}" if last else "")
                + f" (Ray's log: {self.log})")

    def stop(self) -> None:
        """Stop every process of the cluster and wait for `ray start`: once the cluster is
        up, SIGTERM to `ray start`, which stops the rest (SIGKILL to its process group,
        which holds them all, after STOP_TIMEOUT_S); while it starts, SIGKILL to the
        group at once (`ray start` takes a SIGTERM only between steps of its start: 9 s
        measured on a busy machine, against 0.8 s once up)."""
        self._stopping = True
        self.background.cancel()
        if self.process.poll() is None:
            if self._up:
                self.process.terminate()
                try:
                    self.process.wait(STOP_TIMEOUT_S)
                except subprocess.TimeoutExpired:
                    self._kill_group()
            else:
                self._kill_group()
        if not self._failed:
            shutil.rmtree(self.directory, ignore_errors=True)

    def _kill_group(self) -> None:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(self.process.pid, signal.SIGKILL)
        self.process.wait()


def local_head(workers: int) -> LocalHead:
    """A `LocalHead` for `workers` worker actors (at least two CPUs: the statistical
    engine's tasks and the shards need one beside a worker). Its workers run at this
    process's priority unless the user set one: Ray lowers them by 15, and on a busy
    machine a search's workers then lose the cores to everything else, where the same
    search in one process would not."""
    niceness = env_value(EnvVar.RAY_WORKER_NICENESS) or "0"
    return LocalHead(max(2, workers), {**worker_env(), "RAY_worker_niceness": niceness})
