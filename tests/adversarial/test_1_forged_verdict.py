"""Failure 1: anyone who can reach the router decided the verdict.

Before: ten forged RobotStatus "arrived" messages ended a run PASSED with
negative arrival times, one forged Collision failed a good run, any bytes on
/twinfleet/shutdown stopped the fleet. Now: the router admits only the
launch's logins, the monitor login cannot publish, and what the fleet's own
operator login publishes without the fleet key is dropped and counted
(``rejected_forged``) before any handler or the report sees it.
"""

from __future__ import annotations

import json

import pytest
import zenoh

from tests.adversarial.harness import (
    client,
    envelope,
    honest_result,
    poll,
    put,
    running_fleet,
    stats,
    wait_matched,
    write_scenario,
)
from tests.integration.itest_support import run_cli_in

pytestmark = [pytest.mark.slow, pytest.mark.timeout(90)]


def forgeries(fleet: str) -> list[tuple[str, bytes]]:
    arrived = [(f"/{r}/status", envelope("twinfleet_msgs/RobotStatus", {
        "robot": r, "mode": "arrived", "cell": [5, 15], "goal": [5, 15], "waits": 0,
        "failures": 0, "time_ms": -12_200}, sender=r, seq=10_000 + i))
        for i in range(5) for r in ("r1", "r2")]
    collision = ("/collisions", envelope("twinfleet_msgs/Collision", {
        "robot_a": "r1", "robot_b": "r2", "cell_a": [5, 5], "cell_b": [5, 6], "time_ms": 1},
        sender="map_server"))
    shutdown = ("/twinfleet/shutdown", envelope("std_msgs/String", {"data": "forged"},
                                               sender="map_server"))
    poses = [("/poses", envelope("twinfleet_msgs/RobotPose", {
        "robot": "r1", "cell": [25, 6], "direction": 0, "velocity": 1}, sender="r1", seq=i))
        for i in range(20)]
    return [*arrived, collision, shutdown, *poses]


def test_outsiders_cannot_join_and_unsigned_samples_never_reach_a_verdict(tmp_path) -> None:
    with running_fleet(tmp_path, "forge", goal=25, scale=2.0) as fleet:
        for login in (None, ("node", "guessed"), ("monitor", "guessed")):
            with pytest.raises(zenoh.ZError):
                client(fleet.endpoint, login).close()
        monitor = client(fleet.endpoint, fleet.login("monitor"))
        operator = client(fleet.endpoint, fleet.login("operator"))
        try:
            heard: list[bytes] = []
            sub = monitor.declare_subscriber(f"twinfleet/{fleet.fleet}/poses",
                                             lambda s: heard.append(s.payload.to_bytes()))
            assert poll(lambda: heard, 10), "the monitor login cannot read the fleet"
            sub.undeclare()
            wait_matched(operator, fleet.fleet, "/poses")
            for topic, payload in forgeries(fleet.fleet):
                put(monitor, fleet.fleet, topic, payload)  # denied by the router's ACL
                put(operator, fleet.fleet, topic, payload)  # admitted, but not signed
            counted = poll(lambda: (stats(monitor, fleet.fleet, "map_server") or {})
                           .get("rejected_forged", 0) >= 20, 10)
            assert counted, stats(monitor, fleet.fleet, "map_server")
            assert stats(monitor, fleet.fleet, "map_server")["rejected_forged"] == 20  # not 40
            _monitor_with_credentials_file_only(fleet, tmp_path)
        finally:
            monitor.close()
            operator.close()
        code = fleet.wait_end(60)
        out = fleet.output()
    assert "shutdown requested by map_server: all robots arrived" in out, out[-3000:]
    assert "forged" not in out.split("run ended:")[1].split("\n")[0]
    assert "collisions: none" in out, out[-2000:]
    assert honest_result(out, code), out[-2000:]
    assert "-12.2" not in out and "refused samples on the report and shutdown topics: forged" in out


def _monitor_with_credentials_file_only(fleet, tmp_path) -> None:
    """A monitor without this machine's registry needs --credentials (a copy of the entry)."""
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    copy = tmp_path / "creds.json"
    copy.write_text(json.dumps(fleet.entry()))
    copy.chmod(0o600)
    args = ("node", "list", "--connect", fleet.endpoint, "--fleet", fleet.fleet)
    without = run_cli_in(elsewhere, *args)
    assert without.returncode == 2 and "cannot reach the Zenoh router" in without.stderr
    listed = run_cli_in(elsewhere, *args, "--credentials", str(copy))
    assert listed.returncode == 0 and "/map_server" in listed.stdout, listed.stderr
    copy.chmod(0o644)
    loose = run_cli_in(elsewhere, *args, "--credentials", str(copy))
    assert loose.returncode == 2 and "chmod 600" in loose.stderr


def test_listen_off_loopback_needs_tls_or_an_explicit_insecure_flag(tmp_path) -> None:
    scenario = write_scenario(tmp_path, "exposed")
    result = run_cli_in(tmp_path, "launch", str(scenario), "--listen", "tcp/0.0.0.0:7447")
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1, result.stderr
    assert "tls/" in lines[0] and "--insecure-listen" in lines[0]
    assert "[launcher]" not in result.stdout  # refused before a router opened
