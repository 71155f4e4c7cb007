"""Deferred service replies over Zenoh (native nodes, tests/checker/deferred_nodes.py):
each caller gets its own answer from a relay that replies from a later handler, and a
reply sent after the caller's timeout leaves the caller's CallError as it was while the
server goes on (its query was finalised, no error)."""

from __future__ import annotations

import pytest

from tests.checker.deferred_nodes import Answer, Asker, Backend, Relay, SlowRelay
from tests.support import child_env
from twinfleet import testing

pytestmark = [pytest.mark.slow, pytest.mark.fleet, pytest.mark.timeout(120)]


@pytest.fixture(autouse=True)
def _env(monkeypatch: pytest.MonkeyPatch) -> None:
    for key, value in child_env().items():
        monkeypatch.setenv(key, value)


def test_each_caller_gets_its_own_deferred_reply_live():
    system = testing.system({"backend": Backend, "relay": Relay, "a0": Asker, "a1": Asker})

    async def both(fleet: testing.LiveFleet) -> None:
        for name in ("a0", "a1"):
            got = await fleet.message("/answered", lambda m, name=name: m.to == name,
                                      timeout_s=20)
            assert got == Answer(name, name)

    result = testing.run_live(system, both, timeout_s=60)
    assert result.ok and set(result.exit_codes.values()) == {0}, result


def test_a_reply_after_the_callers_timeout_is_the_callers_call_error():
    system = testing.system({"relay": SlowRelay, "a0": Asker})

    async def late(fleet: testing.LiveFleet) -> None:
        got = await fleet.message("/answered", timeout_s=20)
        assert got == Answer("a0", "error")  # the 1 s timeout came first
        assert await fleet.message("/late", timeout_s=20) == Answer("", "replied")
        with pytest.raises(TimeoutError):  # the late reply reached no handler
            await fleet.message("/answered", lambda m: m.to != "a0" or m.text != "error",
                                timeout_s=1.0)

    result = testing.run_live(system, late, timeout_s=60)
    assert result.ok and set(result.exit_codes.values()) == {0}, result
