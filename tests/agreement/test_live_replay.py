"""`twinfleet replay TRACE --live`: checker traces re-enacted by gated nodes.

The fast tests run the gated hosts and the coordinator in one process over
the loopback transport; the slow ones take the C2a counterexample from the
checker and replay it on the real multi-process fleet over Zenoh.
"""

from __future__ import annotations

import asyncio
import contextlib
import io
import json
import os
import signal
from dataclasses import replace
from pathlib import Path

import pytest

from twinfleet.agreement import validate as v
from twinfleet.agreement.live_replay import (
    Coordinator,
    LiveReplayResult,
    Plan,
    compare_node_logs,
    plan,
    replay_live,
)
from twinfleet.checker.driver import CheckOptions, check
from twinfleet.runtime.core.eventlog import EventLog
from twinfleet.runtime.host.node_host import NodeHost
from twinfleet.runtime.host.replay_gate import LogicalClock
from twinfleet.runtime.host.replay_wire import logs_digest
from twinfleet.runtime.host.transport import LoopbackBus, LoopbackTransport

ROOT = Path(__file__).resolve().parents[2]
HEADON = ROOT / "twinfleet" / "launch" / "headon.yaml"
C2A = ROOT / "twinfleet" / "launch" / "c2a.yaml"


def trace_of(scenario: Path, out: Path) -> Path:
    result = check(scenario, CheckOptions(trace_out=str(out)))
    assert result.violation is not None and result.violation.property == "no_collision"
    return out


@pytest.fixture(scope="module")
def headon_plan(tmp_path_factory: pytest.TempPathFactory) -> Plan:
    return plan(trace_of(HEADON, tmp_path_factory.mktemp("headon") / "headon.trace.json"))


async def replay_in_process(p: Plan, events: Path, *,
                            step_timeout_s: float = 5.0) -> LiveReplayResult:
    """Gated hosts of the plan's scenario on one loopback bus, driven by a Coordinator."""
    bus = LoopbackBus()
    names = tuple(cfg.name for cfg in p.scenario.nodes)
    events.mkdir()
    hosts, logs = [], []
    for cfg in p.scenario.nodes:
        transport = LoopbackTransport(bus)
        await transport.open()
        log = EventLog(str(events / f"{cfg.name}.jsonl"), node=cfg.name)
        logs.append(log)
        hosts.append(NodeHost(cfg.instantiate(), transport, LogicalClock(), seed=1,
                              fleet=p.scenario.fleet, wait_for=names, gated=True, events=log,
                              out=io.StringIO()))
    tasks = [asyncio.create_task(h.run()) for h in hosts]
    result = LiveReplayResult(p.trace_path, "no_collision", "", len(p.steps))
    coordinator = Coordinator(p, result, step_timeout_s=step_timeout_s)
    transport = LoopbackTransport(bus)
    await transport.open()
    try:
        result.fleet_reason = await coordinator.run(transport)
    finally:
        for h in hosts:
            h.stop()
        await asyncio.gather(*tasks)
        for log in logs:
            log.close()
    return result


def test_gated_hosts_follow_the_trace_and_show_its_collision(headon_plan, tmp_path):
    result = asyncio.run(asyncio.wait_for(replay_in_process(headon_plan, tmp_path / "ev"), 60))
    assert result.divergence is None, result.divergence
    assert result.granted == len(headon_plan.starts) + len(headon_plan.steps)
    assert result.final_states_match and result.confirmed
    # the trace ends at the collision, which the map server's last handler logs: live too,
    # since every granted handler logged what the checker's run of its step logged
    trace = json.loads(Path(headon_plan.trace_path).read_text())
    assert [log["event"] for log in trace["steps"][-1]["logs"]] == ["collision"]
    assert all(g.logs is not None for g in headon_plan.steps)
    assert "every granted handler logged what its trace step logged" in result.summary()


def test_a_handler_that_logs_otherwise_than_the_trace_stops_the_replay(headon_plan, tmp_path):
    steps = list(headon_plan.steps)
    steps[-1] = replace(steps[-1], logs=logs_digest(()))  # as if the collision were not logged
    result = asyncio.run(asyncio.wait_for(
        replay_in_process(replace(headon_plan, steps=steps), tmp_path / "ev"), 60))
    assert result.divergence is not None and not result.confirmed
    assert result.divergence.startswith(f"step {steps[-1].grant.step}: map_server.")
    assert "ctx.log records differ from the checker's run of the step" in result.divergence


def test_a_state_the_live_node_does_not_reach_stops_the_replay(headon_plan, tmp_path):
    k = next(k for k, g in enumerate(headon_plan.steps) if g.node == "r1" and g.grant.kind == "reply")
    steps = list(headon_plan.steps)
    steps[k] = replace(steps[k], digest="0" * 24)
    result = asyncio.run(asyncio.wait_for(
        replay_in_process(replace(headon_plan, steps=steps), tmp_path / "ev"), 60))
    assert result.divergence is not None
    assert result.divergence.startswith(f"step {steps[k].grant.step}: r1.on_path (reply) at t=")
    assert "live state digest" in result.divergence and "0" * 24 in result.divergence
    assert result.granted == len(headon_plan.starts) + k
    assert not result.confirmed


def test_an_event_that_never_comes_is_reported_with_what_the_node_holds(headon_plan, tmp_path):
    steps = list(headon_plan.steps)
    k = next(k for k, g in enumerate(steps) if g.node == "map_server" and g.grant.kind == "delivery")
    steps[k] = replace(steps[k], grant=replace(steps[k].grant, args="feedfacefeedface"))  # a
    # pose nobody sent
    result = asyncio.run(asyncio.wait_for(replay_in_process(
        replace(headon_plan, steps=steps), tmp_path / "ev", step_timeout_s=0.5), 60))
    assert result.divergence is not None and "did not run on_pose" in result.divergence
    held = result.divergence.split("node holds: ", 1)[1]
    assert "on_pose(RobotPose(robot='r1'" in held and "(delivery from r1)" in held


def test_node_logs_of_an_in_process_replay_match_the_trace(headon_plan, tmp_path):
    result = asyncio.run(asyncio.wait_for(replay_in_process(headon_plan, tmp_path / "ev"), 60))
    assert result.confirmed
    merged = tmp_path / "events.jsonl"
    lines = []
    for part in sorted((tmp_path / "ev").glob("*.jsonl")):
        lines += part.read_text().splitlines()
    merged.write_text("\n".join(lines) + "\n")
    ok, detail = compare_node_logs(headon_plan, str(merged))
    assert ok, detail
    # the replayed run is timed by the trace itself: the checker's exact rules explain it
    strict = v.validate(merged, HEADON, tolerance_ms=0)
    assert strict.ok and strict.events == len(headon_plan.steps), strict.summary()


# ------------------------------------------------------------------ real processes


def _my_node_processes() -> list[int]:
    """Node processes started by this test process (children running runtime.fleet.node_main)."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        with contextlib.suppress(OSError, IndexError, ValueError):
            ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            if ppid == os.getpid() and b"twinfleet.runtime.fleet.node_main" in (entry / "cmdline").read_bytes():
                found.append(int(entry.name))
    return found


@pytest.fixture
def reap_nodes():
    """Kill any node process this test started that is still there at the end."""
    yield
    for pid in _my_node_processes():
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)


@pytest.mark.slow
@pytest.mark.timeout(120)
def test_c2a_counterexample_replayed_live_collides_the_same_way(tmp_path, reap_nodes):
    trace = trace_of(C2A, tmp_path / "c2a.trace.json")
    p = plan(trace)
    out = io.StringIO()
    events = tmp_path / "replay.events.jsonl"
    result = asyncio.run(asyncio.wait_for(
        replay_live(trace, out=out, events_out=str(events), timeout_s=90), 110))
    text = out.getvalue()
    assert result.divergence is None, result.divergence + text[-3000:]
    assert result.granted == len(p.starts) + len(p.steps) > 1000
    assert result.final_states_match
    # the live map server logged exactly the checker's collision: same robots, same cells
    (log,) = json.loads(trace.read_text())["steps"][-1]["logs"]
    assert f"[map_server] t={p.steps[-1].grant.t} collision cells='{log['cells']}' " \
           f"robots='{log['robots']}'" in text
    assert result.node_logs_match, result.node_logs
    assert result.confirmed
    # the nodes' own event logs of the replay are a path of the checker, even strictly timed
    strict = v.validate(events, C2A, tolerance_ms=0)
    assert strict.ok, strict.summary()
    assert strict.violations[0][1] == "no_collision"
    assert not _my_node_processes()


@pytest.mark.slow
@pytest.mark.timeout(120)
def test_replay_live_command(tmp_path, capsys, reap_nodes):
    from twinfleet.cli import main

    trace = trace_of(C2A, tmp_path / "c2a.trace.json")
    assert main(["replay", str(trace), "--live", "--quiet"]) == 1
    assert "live replay CONFIRMED: no_collision" in capsys.readouterr().out
    assert main(["replay", str(trace), "--quiet"]) == 1  # without --live: the checker's replay
    assert "replay confirmed" in capsys.readouterr().out


def lasso_trace(tmp_path: Path) -> Path:
    """A liveness counterexample: a ball goes back and forth for ever, nobody scores."""
    from tests.checker.helpers import node, scenario

    path = scenario(tmp_path, [node("server", "BallServer"), node("returner", "BallReturner")],
                    name="rally", properties=[{"name": "someone_scores", "kind": "eventually",
                                               "expr": "server.scored"}])
    out = tmp_path / "rally.trace.json"
    result = check(path, CheckOptions(trace_out=str(out)))
    assert result.violation is not None and result.violation.shape == "lasso"
    return out


def test_a_lasso_goes_round_its_cycle_again_on_gated_hosts(tmp_path):
    trace = lasso_trace(tmp_path)
    once, thrice = plan(trace, cycles=0), plan(trace, cycles=3)
    # 4 recorded steps, the cycle from world 1 is the last 3 of them
    assert len(once.steps) == 4 and len(thrice.steps) == 4 + 3 * 3
    assert [g.grant.handler for g in thrice.steps[1:4]] == [g.grant.handler for g in thrice.steps[-3:]]
    assert [g.grant.t for g in thrice.steps[-3:]] == [g.grant.t + 30 for g in thrice.steps[1:4]]
    assert thrice.final_digests == once.final_digests  # same states, 30 ms later
    result = asyncio.run(asyncio.wait_for(replay_in_process(thrice, tmp_path / "ev"), 60))
    assert result.divergence is None and result.final_states_match
    assert result.granted == len(thrice.starts) + 13


def test_a_node_the_trace_never_runs_is_compared_by_its_initial_state(tmp_path):
    """A bystander that no step runs (no start handler, nothing it hears is sent) ends in its
    initial state, live as in the checker: the final states still match."""
    from tests.checker.helpers import node, scenario

    path = scenario(tmp_path, [node("server", "BallServer"), node("returner", "BallReturner"),
                               node("bystander", "Summer")],
                    name="watched", properties=[{"name": "someone_scores", "kind": "eventually",
                                                 "expr": "server.scored"}])
    out = tmp_path / "watched.trace.json"
    assert check(path, CheckOptions(trace_out=str(out))).violation is not None
    p = plan(out)
    assert "bystander" not in {g.node for g in (*p.starts, *p.steps)}
    result = asyncio.run(asyncio.wait_for(replay_in_process(p, tmp_path / "ev"), 60))
    assert result.divergence is None and result.final_states_match


@pytest.mark.slow
@pytest.mark.timeout(120)
def test_replay_live_command_runs_a_lasso_cycle_on_real_processes(tmp_path, capsys, reap_nodes):
    from twinfleet.cli import main

    trace = lasso_trace(tmp_path)
    assert main(["replay", str(trace), "--live", "--cycles", "5"]) == 1
    out = capsys.readouterr().out
    assert "lasso: went round the cycle from world 1 5 more time(s); every round came back" in out
    assert "live replay CONFIRMED: someone_scores" in out
    assert main(["replay", str(trace), "--live", "--cycles", "-1"]) == 2
    assert "cycles must be >= 0" in capsys.readouterr().err
    assert not _my_node_processes()


def fault_trace(tmp_path: Path, name: str, props: list[dict], **check_settings) -> Path:
    """A violation of a three-round ping-pong whose /pong takes checker branches."""
    from tests.checker.helpers import node, scenario

    path = scenario(tmp_path, [node("ping", "Ping", rounds=3), node("pong", "Pong")],
                    name=name, properties=props, **check_settings)
    out = tmp_path / f"{name}.trace.json"
    result = check(path, CheckOptions(trace_out=str(out)))
    assert result.violation is not None, result.status
    return out


LATE = [{"name": "quick", "kind": "within", "within_ms": 4, "expr": "ping.sent == 3"}]
FINISHES = [{"name": "finishes", "kind": "deadlock", "expr": "ping.sent == 3 and pong.received == 3"}]


def test_latency_and_drop_branches_are_granted_not_chosen(tmp_path):
    # Two delayed /pongs (shortest: 2 + 3 ms > 4): the grants run ping.on_pong at its delayed
    # time, and the nodes are not asked for the latency branches as ctx.choose answers.
    trace = fault_trace(tmp_path, "late", LATE, latency={"/pong": [0, 3]})
    late = plan(trace)
    assert [(g.grant.handler, g.grant.t) for g in late.steps] == [("on_ping", 0), ("on_pong", 2), ("on_ping", 2)]
    assert [rec["choices"] for rec in json.loads(trace.read_text())["steps"]] == [[2], [], [3]]
    assert all(g.grant.choices == () for g in late.steps)
    result = asyncio.run(asyncio.wait_for(replay_in_process(late, tmp_path / "ev1"), 60))
    assert result.divergence is None and result.final_states_match
    # A dropped /pong: never granted; ping ends waiting, as in the trace.
    lost = plan(fault_trace(tmp_path, "lost", FINISHES, faults={"drop": ["/pong"]}))
    assert [g.grant.handler for g in lost.steps] == ["on_ping"]
    result = asyncio.run(asyncio.wait_for(replay_in_process(lost, tmp_path / "ev2"), 60))
    assert result.divergence is None and result.final_states_match


def test_duplicates_are_refused_and_start_message_branches_are_granted(tmp_path):
    with pytest.raises(ValueError, match="duplicate cannot be replayed live"):
        plan(fault_trace(tmp_path, "dup", [{"name": "once", "kind": "invariant",
                                             "expr": "pong.received <= ping.sent"}],
                         faults={"duplicate": ["/ping"]}))
    with pytest.raises(ValueError, match="timer_lateness cannot be replayed live"):
        plan(fault_trace(tmp_path, "late_timer", [{"name": "one", "kind": "invariant",
                                                    "expr": "ping.sent < 2"}],
                         timer_lateness=[0, 45]))
    # Ping's @on_start publishes the first /ping: its delay is the grant's to take too
    early = plan(fault_trace(tmp_path, "early", LATE, latency={"/ping": [0, 3]}))
    assert all(g.grant.choices == () for g in [*early.starts, *early.steps])
    assert early.steps[0].grant.handler == "on_ping" and early.steps[0].grant.t > 0
    result = asyncio.run(asyncio.wait_for(replay_in_process(early, tmp_path / "ev"), 60))
    assert result.divergence is None and result.final_states_match


@pytest.mark.slow
@pytest.mark.timeout(120)
def test_replay_live_command_runs_a_latency_trace_on_real_processes(tmp_path, capsys, reap_nodes):
    from twinfleet.cli import main

    trace = fault_trace(tmp_path, "late", LATE, latency={"/pong": [0, 3]})
    assert main(["replay", str(trace), "--live"]) == 1
    assert "live replay CONFIRMED: quick" in capsys.readouterr().out
    assert not _my_node_processes()


@pytest.mark.slow
@pytest.mark.timeout(60)
def test_a_violating_simulation_replays_live(tmp_path, capsys, reap_nodes):
    # A simulation's latencies are drawn from the loopback model (1-134 ms): its trace
    # carries them as granted branches, and the live fleet must collide the same way.
    from twinfleet.checker.statistical import StatisticalOptions, check_statistical
    from twinfleet.cli import main

    result = check_statistical(HEADON, StatisticalOptions(
        simulations=8, seed=2, verify=False, traces_out=str(tmp_path), max_traces=1,
        until_decided=True))
    (trace,) = result.traces
    doc = json.loads(Path(trace).read_text())
    assert doc["search"] == "statistical" and doc["latency"] == [1, 134]
    assert any(step["options"] for step in doc["steps"])  # drawn latencies are recorded
    assert main(["replay", trace, "--live", "--quiet"]) == 1
    assert "live replay CONFIRMED: no_collision" in capsys.readouterr().out
    assert not _my_node_processes()
