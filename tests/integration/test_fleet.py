"""Real launcher, real node processes, real Zenoh on 127.0.0.1 (multicast scouting off).

One demo fleet is shared by the monitoring tests (module fixture) and ended by
the last one through `/twinfleet/shutdown`; crash, signals and bad input use
their own small fleets. Every process is cleaned up by a fixture, and every
wait polls a condition with a deadline.
"""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path

import pytest
from itest_support import (
    ROOT,
    child_env,
    fleet_nodes,
    kill_all,
    orphaned_nodes,
    pick_free_port,
    poll,
    run_cli,
    spawned_by,
)

from tests.support import RunningFleet

pytestmark = pytest.mark.slow

DEMO = """\
name: itest
seed: 3
nodes:
  - {name: talker, class: "twinfleet.nodes.demo:Talker", params: {period_ms: 100}}
  - {name: listener, class: "twinfleet.nodes.demo:Listener"}
  - {name: adder, class: "twinfleet.nodes.demo:Adder"}
  - {name: caller, class: "twinfleet.nodes.demo:Caller", params: {period_ms: 200}}
live: {wall_timeout_s: 90}
"""


def start_fleet(tmp: Path, text: str, name: str = "itest", *extra: str) -> RunningFleet:
    """Write a scenario and start `twinfleet launch` on a free loopback port."""
    scenario = tmp / f"{name}.yaml"
    scenario.write_text(text)
    endpoint = f"tcp/127.0.0.1:{pick_free_port()}"
    log = tmp / f"{name}.log"
    with log.open("w") as sink:
        proc = subprocess.Popen([sys.executable, "-m", "twinfleet", "launch", str(scenario),
                                 "--listen", endpoint, "-v", *extra], stdout=sink,
                                stderr=subprocess.STDOUT, env=child_env(), cwd=ROOT)
    return RunningFleet(proc, log, scenario, endpoint, name)


def stop_fleet(fleet: RunningFleet) -> None:
    """Stop a launcher however it is doing; kill leftovers (and let the test fail on them)."""
    if fleet.proc.poll() is None:
        fleet.proc.send_signal(signal.SIGINT)
        try:
            fleet.proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            fleet.proc.kill()
            fleet.proc.wait(timeout=5)
    kill_all(spawned_by(fleet.proc.pid))


def wait_started(fleet: RunningFleet, n: int, timeout: float = 30.0) -> None:
    ok = poll(lambda: fleet.count(r"\] t=-?\d+ started") >= n or fleet.proc.poll() is not None,
              timeout)
    assert ok and fleet.proc.poll() is None, f"fleet did not start:\n{fleet.output()}"


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningFleet]:
    fleet = start_fleet(tmp_path_factory.mktemp("demo"), DEMO)
    try:
        wait_started(fleet, 4)
        yield fleet
    finally:
        stop_fleet(fleet)


def cli(fleet: RunningFleet, *args: str, timeout: float = 20.0) -> subprocess.CompletedProcess[str]:
    return run_cli(*args, "--connect", fleet.endpoint, "--fleet", fleet.fleet, timeout=timeout)


def test_pubsub_service_and_periodic_timer_across_processes(demo: RunningFleet) -> None:
    assert poll(lambda: demo.count(r"\[listener\] t=\d+ heard") >= 5
                and demo.count(r"\[caller\] t=\d+ sum") >= 3, 20), demo.output()
    sums = {int(v) for v in re.findall(r"\[caller\] t=\d+ sum value=(\d+)", demo.output())}
    assert sums <= {11, 12, 13}
    stamps = [int(t) for t in re.findall(r"\[caller\] t=(\d+) sum", demo.output())]
    assert all(b > a for a, b in zip(stamps, stamps[1:], strict=False))  # periodic calls


def test_node_list_from_liveliness(demo: RunningFleet) -> None:
    result = cli(demo, "node", "list")
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ["/adder", "/caller", "/listener", "/talker"]


def test_topic_and_service_list(demo: RunningFleet) -> None:
    topics = cli(demo, "topic", "list", "-v")
    services = cli(demo, "service", "list")
    assert "/chatter  [publishers: talker; subscribers: listener]" in topics.stdout
    assert services.stdout.split() == ["/add_two_ints"]


def test_topic_echo_shows_live_traffic(demo: RunningFleet) -> None:
    result = cli(demo, "topic", "echo", "/chatter", "--count", "3", "--duration", "15")
    assert result.returncode == 0, result.stdout + result.stderr
    assert len(re.findall(r"^data: hello \d+$", result.stdout, re.M)) == 3, result.stdout
    full = cli(demo, "topic", "echo", "/chatter", "--count", "1", "--duration", "15", "--full")
    assert full.stdout.count("type: std_msgs/String") == 1, full.stdout + full.stderr
    assert re.search(r"data: \{data: hello \d+\}", full.stdout)
    assert "sender: talker" in full.stdout


def test_topic_hz_measures_the_talker_rate(demo: RunningFleet) -> None:
    result = cli(demo, "topic", "hz", "/chatter", "--duration", "2.6")
    rates = [float(r) for r in re.findall(r"average rate: ([\d.]+) Hz", result.stdout)]
    assert result.returncode == 0 and rates, result.stdout + result.stderr
    assert 5.0 < rates[-1] < 20.0  # talker period 100 ms; generous on a loaded 2-core box


def test_service_call_and_topic_pub_from_the_cli(demo: RunningFleet) -> None:
    call = cli(demo, "service", "call", "/add_two_ints", "example_interfaces/AddTwoInts_Request",
               "{a: 2, b: 40}", "--module", "twinfleet.nodes.demo")
    assert call.returncode == 0, call.stdout + call.stderr
    assert call.stdout.strip() == "sum: 42"
    missing = cli(demo, "service", "call", "/nothing_here", "std_msgs/Empty")
    assert missing.returncode == 2 and "no server" in missing.stderr
    pub = cli(demo, "topic", "pub", "/chatter", "std_msgs/String", "{data: from-test}")
    assert pub.returncode == 0, pub.stdout + pub.stderr
    assert poll(lambda: "heard data='from-test'" in demo.output(), 10), demo.output()


PLAIN_SCRIPT = """
import glob, hmac, json, os, struct, sys, time, msgpack, zenoh
endpoint, fleet = sys.argv[1], sys.argv[2]
# the fleet's credentials, from its (owner-only) registry entry
entry = next(json.load(open(p)) for p in glob.glob(os.environ["XDG_RUNTIME_DIR"] + "/twinfleet/*.json")
             if json.load(open(p))["endpoint"] == endpoint)
auth = entry["extra"]["auth"]
user, password = auth["operator"]
conf = zenoh.Config()
conf.insert_json5("mode", '"client"')
conf.insert_json5("scouting/multicast/enabled", "false")
conf.insert_json5("transport/shared_memory/enabled", "false")
conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
conf.insert_json5("transport/auth/usrpwd/user", json.dumps(user))
conf.insert_json5("transport/auth/usrpwd/password", json.dumps(password))
got = []
with zenoh.open(conf) as session:
    sub = session.declare_subscriber(f"twinfleet/{fleet}/chatter",
                                     lambda s: got.append(msgpack.unpackb(s.payload.to_bytes())))
    pub = session.declare_publisher(f"twinfleet/{fleet}/chatter",
                                    congestion_control=zenoh.CongestionControl.BLOCK)
    deadline = time.monotonic() + 10
    while (len(got) < 3 or not pub.matching_status) and time.monotonic() < deadline:
        time.sleep(0.05)
    garbage, key = b"\\xc1 garbage from a raw client", f"twinfleet/{fleet}/chatter"
    stamp = struct.pack(">BQQ", 0, 12345, 0)  # role, sender id, sequence number
    tag = hmac.digest(bytes.fromhex(auth["key"]), key.encode() + b"\\0" + stamp + garbage,
                      "sha256")[:16]
    pub.put(garbage, attachment=tag + stamp)  # signed: passes the sender check, fails to decode
    pub.undeclare()
    sub.undeclare()
assert not any(m.split(".")[0] in ("runtime", "nodes", "checker") for m in sys.modules)
print(json.dumps(got[:3]))
"""


def test_plain_zenoh_script_decodes_traffic_and_garbage_is_counted(demo: RunningFleet) -> None:
    result = subprocess.run([sys.executable, "-c", textwrap.dedent(PLAIN_SCRIPT), demo.endpoint,
                             demo.fleet], capture_output=True, text=True, timeout=30,
                            env=child_env(), cwd="/", check=False)
    assert result.returncode == 0, result.stderr
    envelopes = __import__("json").loads(result.stdout)
    assert len(envelopes) == 3
    assert all(e["type"] == "std_msgs/String" and e["sender"] == "talker" for e in envelopes)
    assert poll(lambda: "dropped undecodable sample on twinfleet/itest/chatter" in demo.output(),
                10), demo.output()
    stats = cli(demo, "node", "list", "--stats")
    assert re.search(r"^/listener .*dropped_undecodable=1 .*gaps=0", stats.stdout, re.M), stats.stdout
    assert "handler_errors=0" in stats.stdout


def test_shutdown_topic_ends_the_run_cleanly(demo: RunningFleet) -> None:
    pub = cli(demo, "topic", "pub", "/twinfleet/shutdown", "std_msgs/String", "{data: all done}")
    assert pub.returncode == 0, pub.stdout
    assert poll(lambda: demo.proc.poll() is not None, 20), demo.output()
    out = demo.output()
    assert demo.proc.returncode == 0, out
    assert "run ended: shutdown requested by twinfleet-cli: all done" in out
    assert "Traceback" not in out
    assert re.search(r"\[listener\] stopped: .*gaps=0", out)
    assert poll(lambda: not spawned_by(demo.proc.pid), 5)


CRASH = """\
name: crash
nodes:
  - {name: crasher, class: "twinfleet.nodes.demo:Crasher", params: {crash_after_ms: 200}}
  - {name: listener, class: "twinfleet.nodes.demo:Listener"}
live: {wall_timeout_s: 30, stop_on_error: true}
"""


def test_node_crash_is_reported_and_launch_fails(tmp_path: Path) -> None:
    fleet = start_fleet(tmp_path, CRASH, "crash")
    try:
        assert poll(lambda: fleet.proc.poll() is not None, 40), fleet.output()
        out = fleet.output()
        assert fleet.proc.returncode == 1, out
        assert "[launcher] node crasher exited with code 1; last lines:" in out
        assert "deliberate crash for testing" in out
        assert "run ended: node crasher failed (exit code 1)" in out
        assert "crasher: exit code 1 (FAILED)" in out
        assert "listener: exit code 0 (ok)" in out
        assert poll(lambda: not spawned_by(fleet.proc.pid), 5)
    finally:
        stop_fleet(fleet)


SMALL = """\
name: small
nodes:
  - {name: talker, class: "twinfleet.nodes.demo:Talker", params: {period_ms: 50}}
  - {name: listener, class: "twinfleet.nodes.demo:Listener"}
"""


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGKILL])
def test_signals_to_the_launcher_leave_no_process(tmp_path: Path, sig: signal.Signals) -> None:
    fleet = start_fleet(tmp_path, SMALL, "small", "--time-scale", "2")
    try:
        wait_started(fleet, 2)
        assert len(spawned_by(fleet.proc.pid)) == 2  # its 2 nodes
        fleet.proc.send_signal(sig)
        fleet.proc.wait(timeout=20)
        assert poll(lambda: not spawned_by(fleet.proc.pid), 10), \
            spawned_by(fleet.proc.pid)
        if sig != signal.SIGKILL:  # the launcher ends the run and stops its nodes itself
            expected = 143 if sig == signal.SIGTERM else 130  # interrupted, not failed
            assert fleet.proc.returncode == expected, fleet.output()
            assert f"run ended: {sig.name} received" in fleet.output()
            assert f"result: interrupted ({sig.name} received)" in fleet.output()
            assert re.search(r"\[listener\] stopped: .*gaps=0", fleet.output())
    finally:
        stop_fleet(fleet)


def test_bad_scenario_fails_before_anything_starts(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: bad\nnodes:\n  - {name: r1, class: 'twinfleet.nodes.demo:Nope'}\n")
    result = run_cli("launch", str(bad))
    assert result.returncode == 2
    assert f"{bad}: nodes[0].class: unknown node class 'twinfleet.nodes.demo:Nope'" in result.stderr
    assert "Traceback" not in result.stderr
    assert not orphaned_nodes()


RESPAWN = """\
name: respawn
nodes:
  - {name: crasher, class: "twinfleet.nodes.demo:Crasher", respawn: true, params: {crash_after_ms: 100}}
  - {name: talker, class: "twinfleet.nodes.demo:Talker", params: {period_ms: 50}}
live: {stop_on_error: true}
"""


def test_run_fleet_as_a_library_with_respawn_and_summary(tmp_path: Path) -> None:
    import asyncio
    import dataclasses
    import io

    from twinfleet.runtime.contract.messages import String
    from twinfleet.runtime.fleet.fleet_result import EndReason
    from twinfleet.runtime.fleet.launcher import LaunchOptions, run_fleet
    from twinfleet.runtime.scenario.spec import load_scenario

    path = tmp_path / "respawn.yaml"
    path.write_text(RESPAWN)
    scenario = load_scenario(path)
    scenario = dataclasses.replace(
        scenario, live=dataclasses.replace(scenario.live, summary_topics=("/chatter",)))
    out = io.StringIO()
    result = asyncio.run(asyncio.wait_for(
        run_fleet(scenario, LaunchOptions(time_scale=2.0, timeout_s=6.0, seed=5,
                                          handle_signals=False), out=out),
        40))
    text = out.getvalue()
    assert result.reason == "timeout after 6 s", text
    assert result.end is EndReason.TIMEOUT and not result.interrupted
    assert result.restarts["crasher"] >= 1, text
    assert "[launcher] respawning crasher (restart 1)" in text
    assert result.exit_codes["talker"] == 0 and "talker" not in result.failed
    last = result.last_messages["/chatter"]
    assert isinstance(last, String) and last.data.startswith("hello ")
    assert poll(lambda: not fleet_nodes(), 5)
