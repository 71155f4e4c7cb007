"""Across machines: two network namespaces joined by a veth pair, a fleet split over both.

Host A (namespace A) runs the launcher's Zenoh router, listening on A's veth
address, and a publisher node; host B (namespace B) runs a watcher node whose
launcher joins A's router with ``--connect``. The test shows traffic flowing
from A to B, cuts the link (``ip link set ... down``), shows that B loses A's
liveliness token within the Zenoh lease (1 s here, through
``TWINFLEET_ZENOH_CONFIG_OVERRIDE``), then brings the link up and shows the
token and the traffic come back.

A second test runs the same two hosts over TLS with certificates `launch` makes: host B
joins with ``--credentials`` (a copy of host A's registry entry; each host has a fleet
registry of its own, as two machines do), a monitor on host B lists the fleet, and a
credentials file naming another certificate authority is refused with one line.

Addresses are the test's own: ``10.231.<n>.1/30`` and ``.2/30`` exist only
inside the two namespaces, which are deleted (with the veth pair) in a
``finally``. Needs root and iproute2; skipped with the reason otherwise.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from itest_support import ROOT, child_env, kill_all, poll, spawned_by

from twinfleet.runtime.host.certs import fleet_authority

pytestmark = [pytest.mark.slow, pytest.mark.timeout(90)]

NODES = "tests.integration.reliability_nodes"
LEASE_MS = 1000
PORT = 7447  # a fresh namespace: every port is free


@dataclass(frozen=True)
class Link:
    """Two namespaces and the veth pair between them."""

    ns_a: str
    ns_b: str
    dev_a: str
    dev_b: str
    addr_a: str
    addr_b: str

    def set_a(self, state: str) -> None:
        ip("-n", self.ns_a, "link", "set", self.dev_a, state)


def ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, text=True, timeout=10)


def namespace_pids(ns: str) -> list[int]:
    found = subprocess.run(["ip", "netns", "pids", ns], capture_output=True, text=True,
                           timeout=10, check=False)
    return [int(p) for p in found.stdout.split()]


def delete_namespace(ns: str) -> None:
    kill_all(namespace_pids(ns))
    subprocess.run(["ip", "netns", "del", ns], capture_output=True, timeout=10, check=False)


@pytest.fixture
def link() -> Iterator[Link]:
    if shutil.which("ip") is None:
        pytest.skip("iproute2 (`ip`) is not installed: cannot build network namespaces")
    tag = f"{os.getpid() % 100000}"
    block = os.getpid() % 250
    link = Link(f"tfa{tag}", f"tfb{tag}", f"tfa{tag}v", f"tfb{tag}v",
                f"10.231.{block}.1", f"10.231.{block}.2")
    probe = subprocess.run(["ip", "netns", "add", link.ns_a], capture_output=True, text=True,
                           timeout=10, check=False)
    if probe.returncode != 0:
        pytest.skip(f"cannot create network namespaces (`ip netns add` failed: "
                    f"{probe.stderr.strip() or probe.returncode}); needs root / CAP_SYS_ADMIN")
    try:
        try:
            ip("netns", "add", link.ns_b)
            ip("link", "add", link.dev_a, "type", "veth", "peer", "name", link.dev_b)
            ip("link", "set", link.dev_a, "netns", link.ns_a)
            ip("link", "set", link.dev_b, "netns", link.ns_b)
            for ns, dev, addr in ((link.ns_a, link.dev_a, link.addr_a),
                                  (link.ns_b, link.dev_b, link.addr_b)):
                ip("-n", ns, "addr", "add", f"{addr}/30", "dev", dev)
                ip("-n", ns, "link", "set", dev, "up")
                ip("-n", ns, "link", "set", "lo", "up")
        except subprocess.CalledProcessError as exc:
            pytest.skip(f"cannot build the two test hosts: `{' '.join(exc.cmd)}` failed: "
                        f"{(exc.stderr or '').strip()}")
        yield link
    finally:
        delete_namespace(link.ns_a)  # deleting a namespace deletes its end of the veth pair
        delete_namespace(link.ns_b)


class Launch:
    """A `twinfleet launch` inside a namespace, its output in a file."""

    def __init__(self, tmp: Path, ns: str, name: str, text: str, *args: str,
                 runtime_dir: Path | None = None) -> None:
        self.scenario = tmp / f"{name}.yaml"
        self.scenario.write_text(text)
        self.log = tmp / f"{name}.log"
        env = child_env()
        if runtime_dir is not None:  # another machine: a fleet registry of its own
            env["TWINFLEET_RUNTIME_DIR"] = str(runtime_dir)
        env["TWINFLEET_ZENOH_CONFIG_OVERRIDE"] = (f"transport/link/tx/lease={LEASE_MS};"
                                                  "transport/link/tx/keep_alive=4")
        with self.log.open("w") as sink:
            self.proc = subprocess.Popen(
                ["ip", "netns", "exec", ns, sys.executable, "-m", "twinfleet", "launch",
                 str(self.scenario), "-v", *args], stdout=sink, stderr=subprocess.STDOUT, env=env,
                cwd=ROOT)

    def output(self) -> str:
        return self.log.read_text(errors="replace")

    def wait_line(self, pattern: str, timeout: float, *, after_count: int = 0) -> float:
        """Wall time at which the (after_count+1)-th line matching `pattern` was seen."""
        regex = re.compile(pattern, re.M)
        found = poll(lambda: len(regex.findall(self.output())) > after_count
                     or self.proc.poll() is not None, timeout, interval=0.02)
        assert found and self.proc.poll() is None, \
            f"no {pattern!r} (after {after_count}) within {timeout} s:\n{self.output()}"
        return time.monotonic()

    def count(self, pattern: str) -> int:
        return len(re.findall(pattern, self.output(), re.M))

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=5)
        kill_all(spawned_by(self.proc.pid))


def test_a_cut_link_is_detected_within_the_lease_and_recovers(tmp_path: Path,
                                                               link: Link) -> None:
    router = f"tcp/{link.addr_a}:{PORT}"
    host_a = Launch(tmp_path, link.ns_a, "host_a", f"""\
name: host_a
fleet: xnet
nodes:
  - {{name: talker, class: "{NODES}:Heartbeat", params: {{period_ms: 50}}}}
""", "--listen", router, "--insecure-listen")  # a test veth pair, not a network
    host_b: Launch | None = None
    try:
        host_a.wait_line(r"^\[talker\] t=-?\d+ started", 30)
        host_b = Launch(tmp_path, link.ns_b, "host_b", f"""\
name: host_b
fleet: xnet
nodes:
  - {{name: watcher, class: "{NODES}:Watcher", params: {{watch: [talker]}}}}
""", "--connect", router)
        heard = r"^\[watcher\] t=\d+ heard sender='talker'"
        host_b.wait_line(r"^\[watcher\] t=\d+ alive node='talker'", 30)
        host_b.wait_line(heard, 15, after_count=2)  # traffic flows from A to B

        cut = time.monotonic()
        link.set_a("down")
        lost = host_b.wait_line(r"^\[watcher\] t=\d+ lost node='talker'", 10)
        heard_while_cut = host_b.count(heard)
        time.sleep(0.5)
        assert host_b.count(heard) == heard_while_cut  # nothing crosses a cut link

        restored = time.monotonic()
        link.set_a("up")
        back = host_b.wait_line(r"^\[watcher\] t=\d+ back node='talker'", 30)
        host_b.wait_line(heard, 15, after_count=heard_while_cut + 1)  # traffic again
        print(f"\nnetns figures: {{\"lease_ms\": {LEASE_MS}, "
              f"\"detect_s\": {lost - cut:.2f}, \"recover_s\": {back - restored:.2f}}}")
        assert lost - cut < 2 * LEASE_MS / 1000 + 0.5, host_b.output()
        for launch in (host_b, host_a):
            launch.stop()
            assert launch.proc.returncode == 130, launch.output()  # Ctrl-C: interrupted
            assert "run ended: SIGINT received" in launch.output()
            assert not spawned_by(launch.proc.pid)
        lost_on_the_way = re.search(r"^\[watcher\] stopped: .*\bgaps=(\d+)", host_b.output(), re.M)
        assert lost_on_the_way and int(lost_on_the_way.group(1)) > 0  # the cut shows as gaps
    finally:
        for launch in (host_b, host_a):
            if launch is not None:
                launch.stop()


def own_registry(tmp: Path, name: str) -> Path:
    """A fleet registry directory for one test host (owner-only, as the registry wants)."""
    path = tmp / name
    path.mkdir(mode=0o700)
    return path


def run_in(ns: str, runtime_dir: Path, *args: str) -> subprocess.CompletedProcess[str]:
    """`python -m twinfleet ARGS` inside namespace `ns`, with that host's registry."""
    env = child_env()
    env["TWINFLEET_RUNTIME_DIR"] = str(runtime_dir)
    return subprocess.run(["ip", "netns", "exec", ns, sys.executable, "-m", "twinfleet", *args],
                          capture_output=True, text=True, timeout=30, env=env, cwd=ROOT,
                          check=False)


def test_a_fleet_over_tls_with_certificates_made_by_launch(tmp_path: Path, link: Link) -> None:
    router = f"tls/{link.addr_a}:{PORT}"
    registry_a, registry_b = own_registry(tmp_path, "reg_a"), own_registry(tmp_path, "reg_b")
    host_a = Launch(tmp_path, link.ns_a, "tls_a", f"""\
name: tls_a
fleet: xtls
nodes:
  - {{name: talker, class: "{NODES}:Heartbeat", params: {{period_ms: 50}}}}
""", "--listen", router, runtime_dir=registry_a)  # no --insecure-listen: tls/ needs none
    host_b: Launch | None = None
    try:
        host_a.wait_line(r"^\[talker\] t=-?\d+ started", 30)
        entry = re.search(r"--credentials FILE, FILE a copy of (\S+)", host_a.output())
        assert entry, host_a.output()
        credentials = tmp_path / "xtls-credentials.json"  # copied to host B, owner-only
        credentials.write_bytes(Path(entry.group(1)).read_bytes())
        credentials.chmod(0o600)
        assert "tls_ca" in credentials.read_text()
        server_pem = Path(entry.group(1)).with_suffix(".server.pem")
        assert server_pem.stat().st_mode & 0o777 == 0o600  # the router's key: owner-only

        host_b = Launch(tmp_path, link.ns_b, "tls_b", f"""\
name: tls_b
fleet: xtls
nodes:
  - {{name: watcher, class: "{NODES}:Watcher", params: {{watch: [talker]}}}}
""", "--connect", router, "--credentials", str(credentials), runtime_dir=registry_b)
        host_b.wait_line(r"^\[watcher\] t=\d+ alive node='talker'", 30)
        host_b.wait_line(r"^\[watcher\] t=\d+ heard sender='talker'", 15, after_count=2)

        listed = run_in(link.ns_b, registry_b, "node", "list", "--connect", router,
                        "--credentials", str(credentials))  # a monitor on host B
        assert listed.returncode == 0 and "xtls:/talker" in listed.stdout, listed

        wrong = json.loads(credentials.read_text())
        wrong["extra"]["auth"]["tls_ca"] = fleet_authority("elsewhere").certificate.decode()
        wrong_file = tmp_path / "wrong-ca.json"
        wrong_file.write_text(json.dumps(wrong))
        wrong_file.chmod(0o600)
        refused = run_in(link.ns_b, registry_b, "node", "list", "--connect", router,
                         "--credentials", str(wrong_file))
        lines = refused.stderr.strip().splitlines()
        assert refused.returncode != 0 and len(lines) == 1, refused
        assert "certificate" in lines[0] and "--credentials" in lines[0], lines[0]
        assert "Traceback" not in refused.stderr
        for launch in (host_b, host_a):
            launch.stop()
            assert launch.proc.returncode == 130, launch.output()
    finally:
        for launch in (host_b, host_a):
            if launch is not None:
                launch.stop()
