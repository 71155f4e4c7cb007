"""twinfleet.testing: systems built in Python, checked, replayed and run live."""

from __future__ import annotations

import asyncio
import os
from pathlib import Path

import pytest

from tests.checker.models import Ping, Pong
from tests.support import child_env
from twinfleet import testing
from twinfleet.cli import main
from twinfleet.runtime.fleet.fleet_result import EndReason

pytestmark = pytest.mark.timeout(60)


def ping_pong(rounds: int = 3, bound: str = "ping.sent - pong.received <= 1"):
    return testing.system({"ping": (Ping, {"rounds": rounds}), "pong": Pong},
                          [testing.invariant("bounded", bound),
                           testing.eventually("all_answered", f"pong.received == {rounds}")],
                          name="pingpong")


def test_a_system_that_holds_reports_the_counts():
    result = testing.check(ping_pong())
    assert result.holds and not result.violated and not result.breach, result.explain()
    # 3 rounds: ping, pong, ping, pong, ping, pong: 7 worlds, 6 steps (tests/checker).
    assert (result.states, result.transitions) == (7, 6)
    assert result.explain().startswith("holds: every property holds (7 states, 6 transitions")
    assert result.trace is None and result.property is None


def test_a_violation_explains_itself_and_replays(tmp_path, capsys):
    result = testing.check(ping_pong(bound="pong.received < 2"))
    assert result.violated and result.property == "bounded"
    text = result.explain()
    assert "violated: invariant 'pong.received < 2' is false" in text
    assert "pong.on_ping (delivery from ping, Num(value=2))" in text
    path = result.save_trace(tmp_path / "pp.trace.json")
    assert Path(f"{path}.scenario.yaml").is_file()
    assert main(["replay", str(path)]) == 1  # confirmed, from the file alone
    assert "replay confirmed: bounded violated" in capsys.readouterr().out
    with pytest.raises(ValueError, match="no trace to save"):
        testing.check(ping_pong()).save_trace(tmp_path / "none.json")


def test_a_breach_is_a_verdict_of_its_own():
    from tests.checker.mistakes import AttributeCounter, BadInitialState

    result = testing.check(testing.system({"n1": AttributeCounter}))
    assert result.breach and not result.holds
    assert "node n1, handler tick (@handler)" in result.message
    early = testing.check(testing.system({"n1": BadInitialState}))
    assert early.breach and "node n1, handler initial_state" in early.message
    assert any("imports random" in w for w in result.warnings)


def test_check_takes_options_and_files(tmp_path):
    limited = testing.check(ping_pong(rounds=50), max_states=3)
    assert limited.verdict == "unknown" and "max-states" in limited.message
    assert testing.check("demo", max_states=200).verdict == "unknown"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


@pytest.mark.slow
@pytest.mark.fleet
def test_a_live_fleet_hears_and_cleans_up_even_when_the_test_fails(monkeypatch):
    for key, value in child_env().items():
        monkeypatch.setenv(key, value)
    pids: list[int] = []

    async def failing() -> None:
        async with testing.live_fleet("demo", time_scale=5, timeout_s=30) as fleet:
            assert fleet.endpoint.startswith("tcp/127.0.0.1:")
            msg = await fleet.message("/chatter", lambda m: m.data.endswith(" 3"))
            assert msg.data == "hello 3"
            pids.extend(fleet.pids.values())
            raise RuntimeError("the test failed here")

    with pytest.raises(RuntimeError, match="the test failed here"):
        asyncio.run(failing())
    assert len(pids) == 4 and not any(_alive(pid) for pid in pids)


@pytest.mark.slow
@pytest.mark.fleet
def test_a_test_that_ends_at_once_still_finds_every_node_running(monkeypatch):
    for key, value in child_env().items():
        monkeypatch.setenv(key, value)

    async def nothing(fleet: testing.LiveFleet) -> None:
        assert set(fleet.pids) == {"talker", "listener", "adder", "caller"}

    result = testing.run_live("demo", nothing, time_scale=5, timeout_s=30)
    assert result.ok, result  # every node was up, then stopped cleanly (no exit by signal)
    assert set(result.exit_codes.values()) == {0}


@pytest.mark.slow
@pytest.mark.fleet
def test_run_live_publishes_into_the_fleet_and_times_out_clearly(monkeypatch):
    for key, value in child_env().items():
        monkeypatch.setenv(key, value)
    from twinfleet import String

    async def talk(fleet: testing.LiveFleet) -> None:
        await fleet.message("/chatter")  # the talker runs
        fleet.publish("/chatter", String("from the test"))
        heard = await fleet.message("/chatter", lambda m: m.data == "from the test")
        assert heard == String("from the test")
        with pytest.raises(TimeoutError, match="no matching message on /nothing"):
            await fleet.message("/nothing", timeout_s=0.3)

    result = testing.run_live("demo", talk, time_scale=5, timeout_s=30)
    assert result.ok and result.reason == "the test finished"
    assert result.end is EndReason.DRIVER
