"""Helpers of the adversarial tests: a small live fleet on loopback, and a hostile client.

Each test starts its own fleet (`running_fleet`): a map server and two robots
on map50 with the run report, `twinfleet launch --listen tcp/127.0.0.1:<free
port>`, its output in a log file. The hostile side is a plain Zenoh client
(`client`) that may hold no login, the read-only monitor login or the
operator login of the fleet's registry entry, and may or may not sign what it
sends with the fleet key (`put`). Traffic is always bounded: a handful of
messages, or one large one.
"""

from __future__ import annotations

import contextlib
import glob
import json
import re
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import msgpack
import zenoh

from tests.support import ROOT, RUNTIME_DIR, RunningFleet, child_env, pick_free_port
from twinfleet.runtime.core.guard import sign
from twinfleet.runtime.host.zenoh_transport import zenoh_config

SCENARIO = """\
name: {name}
seed: 1
params: {{map: {root}/twinfleet/maps/map50.yaml, profile: fixed, scan_rate_ms: 100}}
nodes:
- {{name: map_server, class: "twinfleet.nodes.map_server:MapServer", priority: 1,
    params: {{robots: [r1, r2]}}}}
- {{name: r1, class: "twinfleet.nodes.robot:Robot", namespace: /r1, priority: 2,
    params: {{start: [5, 5], goal: [5, {goal}], speed: 1.0, max_wait_ms: 1500}}}}
- {{name: r2, class: "twinfleet.nodes.robot:Robot", namespace: /r2, priority: 3,
    params: {{start: [25, 5], goal: [25, {goal}], speed: 1.0, max_wait_ms: 1500}}}}
properties:
- {{name: no_collision, kind: invariant, expr: "map_server.collisions == 0"}}
live: {{wall_timeout_s: 60, time_scale: {scale}, report: "twinfleet.nodes.report:report_for"}}
"""


def poll(predicate: Any, timeout: float, interval: float = 0.05) -> Any:
    """Poll until `predicate()` is truthy or `timeout` s pass; return its last value."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value or time.monotonic() >= deadline:
            return value
        time.sleep(interval)


class LiveFleet(RunningFleet):
    """A running `twinfleet launch` of `SCENARIO`, with its registry entry."""

    def entry(self) -> dict[str, Any]:
        """The fleet's registry entry (its credentials are in ``extra.auth``)."""
        for path in glob.glob(f"{RUNTIME_DIR}/twinfleet/*.json"):
            with contextlib.suppress(OSError, ValueError):
                doc = json.loads(Path(path).read_text())
                if doc.get("endpoint") == self.endpoint:
                    return doc
        raise AssertionError(f"no registry entry for {self.endpoint}")

    @property
    def key(self) -> bytes:
        return bytes.fromhex(self.entry()["extra"]["auth"]["key"])

    def login(self, role: str) -> tuple[str, str]:
        user, password = self.entry()["extra"]["auth"][role]
        return user, password

    def wait_end(self, timeout: float = 60.0) -> int:
        return self.proc.wait(timeout=timeout)


def write_scenario(tmp: Path, name: str, *, goal: int = 15, scale: float = 2.0) -> Path:
    path = tmp / f"{name}.yaml"
    path.write_text(SCENARIO.format(name=name, root=ROOT, goal=goal, scale=scale))
    return path


def launch(scenario: Path, log: Path, *args: str) -> subprocess.Popen:
    with log.open("w") as sink:
        # -v: every node's full counters at the end, which these tests read
        return subprocess.Popen([sys.executable, "-m", "twinfleet", "launch", str(scenario), "-v",
                                 *args],
                                stdout=sink, stderr=subprocess.STDOUT, env=child_env(), cwd=ROOT,
                                start_new_session=True)


@contextlib.contextmanager
def running_fleet(tmp: Path, name: str, *, goal: int = 15, scale: float = 2.0,
                  nodes: int = 3) -> Iterator[LiveFleet]:
    """Start the fleet, wait until its `nodes` nodes started, stop it (and leftovers) after."""
    scenario = write_scenario(tmp, name, goal=goal, scale=scale)
    endpoint = f"tcp/127.0.0.1:{pick_free_port()}"
    log = tmp / f"{name}.log"
    fleet = LiveFleet(launch(scenario, log, "--listen", endpoint), log, scenario, endpoint, name)
    try:
        started = poll(lambda: len(re.findall(r"\] t=-?\d+ started", fleet.output())) >= nodes
                       or fleet.proc.poll() is not None, 30)
        assert started and fleet.proc.poll() is None, fleet.output()
        yield fleet
    finally:
        stop(fleet.proc)


def stop(proc: subprocess.Popen) -> None:
    """SIGINT, then SIGKILL of the whole process group (the launcher and its nodes)."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError):
                import os
                os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=5)


def client(endpoint: str, login: tuple[str, str] | None = None) -> zenoh.Session:
    """A plain Zenoh client session (raises `zenoh.ZError` when the router refuses it)."""
    settings = None
    if login is not None:
        settings = {"transport/auth/usrpwd/user": login[0],
                    "transport/auth/usrpwd/password": login[1]}
    return zenoh.open(zenoh_config(connect=[endpoint], mode="client", settings=settings))


def envelope(type_name: str, data: dict[str, Any], *, sender: str, seq: int = 1,
             stamp_ms: int = 0) -> bytes:
    """A twinfleet envelope built by hand (as an attacker would, with any field values)."""
    return msgpack.packb({"type": type_name, "stamp_ms": stamp_ms, "seq": seq, "sender": sender,
                          "data": data}, use_bin_type=True)


def put(session: zenoh.Session, fleet: str, topic: str, payload: bytes,
        key: bytes | None = None) -> None:
    """Publish `payload` on the fleet's `topic`, signed with `key` if given."""
    where = f"twinfleet/{fleet}{topic}"
    session.put(where, payload, attachment=sign(key, where, payload) if key else None,
                congestion_control=zenoh.CongestionControl.BLOCK)


def stats(session: zenoh.Session, fleet: str, node: str, timeout: float = 2.0
          ) -> dict[str, Any] | None:
    """A node's @stats, or None when it does not answer within `timeout` s."""
    for reply in session.get(f"twinfleet/{fleet}/@stats/{node}", timeout=timeout):
        if reply.ok is not None:
            return msgpack.unpackb(reply.ok.payload.to_bytes())
    return None


def wait_matched(session: zenoh.Session, fleet: str, topic: str, timeout: float = 5.0) -> None:
    """Wait until some subscriber of the fleet's `topic` is reachable from `session`."""
    pub = session.declare_publisher(f"twinfleet/{fleet}{topic}")
    try:
        poll(lambda: pub.matching_status.matching, timeout)
    finally:
        pub.undeclare()


def honest_result(out: str, code: int) -> bool:
    """The run's own verdict, not one an attacker chose: PASSED (exit 0), CONTRACT BREACH
    (exit 4) for a message of the wrong type, or INCONCLUSIVE (exit 3) where the verdict
    rules count refused samples (`rejected_*`) as a reason."""
    if "result: PASSED" in out:
        return code == 0
    if "result: CONTRACT BREACH (wrong message type" in out:
        # a sample of a type its handler does not take, signed with the fleet key: the
        # verdict the checker gives for such a send (whoever holding the key forged it)
        return code == 4
    return "INCONCLUSIVE" in out and "rejected_" in out and code == 3
