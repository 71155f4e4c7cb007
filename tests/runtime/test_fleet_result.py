"""`FleetResult`: what ended a run is an `EndReason`, read by code; `reason` is for people."""

from __future__ import annotations

import pytest

from twinfleet.runtime.access.connection import EXIT_INTERRUPTED, EXIT_OK
from twinfleet.runtime.contract.kinds import EXIT_TERMINATED
from twinfleet.runtime.fleet.fleet_result import EndReason, FleetResult, RunEnding

pytestmark = pytest.mark.timeout(30)


def result(end: EndReason, reason: str) -> FleetResult:
    return FleetResult(fleet="f", endpoint="tcp/127.0.0.1:1", reason=reason, end=end,
                       exit_codes={"a": 0}, failed=())


def test_the_end_reason_not_its_words_says_whether_a_run_was_interrupted():
    assert result(EndReason.INTERRUPTED, "SIGINT received").interrupted
    assert result(EndReason.INTERRUPTED, "SIGINT received").exit_code == EXIT_INTERRUPTED
    assert result(EndReason.TERMINATED, "SIGTERM received").exit_code == EXIT_TERMINATED
    # a shutdown request whose text happens to begin like a signal is no signal
    said = result(EndReason.SHUTDOWN, "SIGINT from the operator's script")
    assert not said.interrupted and said.exit_code == EXIT_OK


@pytest.mark.parametrize(("code", "kind"), [(-9, EndReason.NODE_KILLED),
                                            (1, EndReason.NODE_FAILED)])
def test_a_node_exit_is_killed_or_failed_by_its_code(code, kind):
    ending = RunEnding.node_exit("r1", code)
    assert ending == RunEnding(kind, f"node r1 failed (exit code {code})")


def test_launch_options_are_one_frozen_value_with_the_scenarios_defaults():
    import dataclasses
    import inspect

    from twinfleet.runtime.fleet.launcher import STARTUP_S, LaunchOptions, run_fleet

    options = LaunchOptions()
    assert (options.time_scale, options.timeout_s, options.seed, options.until_settled) == (
        None, None, None, None)  # the scenario's
    assert options.startup_s == STARTUP_S and options.handle_signals and options.judge
    with pytest.raises(dataclasses.FrozenInstanceError):
        options.seed = 3  # type: ignore[misc]
    # run_fleet takes the scenario, the options, where output goes and the driver: no more
    assert list(inspect.signature(run_fleet).parameters) == ["scenario", "options", "out",
                                                            "driver"]
