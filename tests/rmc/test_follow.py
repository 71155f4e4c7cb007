"""Our `rebeca` system follows RMC's own counterexamples step by step, to the collision.

The traces are data produced by running the Rebeca model checker on the paper's
model (tests/data/rmc/README.md); the follower (tests/rmc/follower.py) compares
every robot and the map server after every step.
"""

from __future__ import annotations

import dataclasses

import pytest

from tests.rmc import adapter
from tests.rmc.follower import follow, follow_case, scenario_path, trace_path
from tests.rmc.rmc_trace import decode_cell, read_trace
from twinfleet.nodes.map_server import MapServer

pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]

CASES = ("c2a", "c2b", "c2c")
#: RMC's reported steps of each counterexample (states in the trace minus one, plus
#: the violating step), from the traces' headers and lengths.
STEPS = {"c2a": 1028, "c2b": 2042, "c2c": 569}


def test_trace_data_is_present_and_complete():
    # CI must not skip the follower silently: the data is part of the repository.
    for case in CASES:
        trace = read_trace(trace_path(case))
        assert trace.violated, case
        assert trace.header["property"]["message"] == "collisionFree"
        assert len(trace.steps) == STEPS[case]
        assert len(trace.states) == STEPS[case]


def test_decode_cell_is_the_models_idx2xy():
    assert decode_cell(10351045) == (45, 35)
    assert decode_cell(10051005) == (5, 5)
    assert decode_cell(20011002) == (2, -1)
    assert decode_cell(109991003) == (3, 999)  # xy2idx(3, 9999): "nothing seen" decodes as 999


@pytest.mark.parametrize("case", CASES)
def test_follower_reproduces_rmcs_counterexample_to_the_collision(case):
    result = follow_case(case)
    assert result.ok, str(result.divergence)
    assert result.steps == STEPS[case]
    assert result.collisions >= 1  # the last step is the collision, as in RMC


def test_initial_plans_in_the_traces_are_ours():
    # Each robot's moves after its first onNewPath, in RMC and in the follower's world.
    trace = read_trace(trace_path("c2a"))
    plans = {}
    for state in trace.states:
        for name, robot in state.robots.items():
            if robot.moves and name not in plans:
                plans[name] = robot.moves
    assert sorted(plans) == ["r1", "r2", "r3", "r4", "r5"]
    system, world = adapter.build(scenario_path("c2a"))
    requests = [p for p in adapter.pending(system, world) if p.handler == "generate_path"]
    server = next(n for n in system.nodes if isinstance(n, MapServer))
    for p in requests:
        req = p.args[0]
        assert server.planner.plan([], tuple(req.start), tuple(req.goal)) == plans[req.robot]


def test_follower_reports_the_first_difference_with_both_values():
    trace = read_trace(trace_path("c2c"))
    k = 40  # tamper with RMC's state after step 39: r3's waypoint index
    state = trace.states[k]
    r3 = dataclasses.replace(state.robots["r3"], move_idx=state.robots["r3"].move_idx + 7)
    tampered_state = dataclasses.replace(state, robots={**state.robots, "r3": r3})
    states = (*trace.states[:k], tampered_state, *trace.states[k + 1:])
    tampered = dataclasses.replace(trace, states=states)
    system, world = adapter.build(scenario_path("c2c"))
    result = follow(system, world, tampered)
    assert not result.ok
    assert result.steps == k - 1
    (diff,) = result.divergence.differences
    assert diff.where == "r3.move_idx"
    assert diff.rmc == diff.ours + 7
    assert "r3.move_idx" in str(result.divergence)
