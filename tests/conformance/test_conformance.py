"""Conformance: one tiny system per contract feature, in the checker and live over Zenoh.

Each case is a scenario of `tests/conformance/systems.py`. The fast test
checks it exhaustively and asserts what the feature means there (its
properties hold, or the one failure it must show); the slow one launches it as
real processes over Zenoh (`twinfleet launch --record-events`, time scale 10)
and asserts with `twinfleet validate` that the live event log is a path of the
checker (untimed: order, choices, failures and every state digest), and that
the live path violates no invariant the checker says holds (except those that
hold only under the model's exact timing: handler priorities).
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
import yaml

from tests.support import ROOT, child_env
from twinfleet.agreement.validate import validate
from twinfleet.checker.driver import CheckOptions, check, load
from twinfleet.checker.system import System
from twinfleet.runtime.scenario.spec import ScenarioError

M = "tests.conformance.systems:"


@dataclass(frozen=True)
class Case:
    """One feature's system: its nodes, properties and what the checker must answer."""

    nodes: list[dict[str, Any]]
    properties: list[dict[str, Any]] = field(default_factory=list)
    status: str = "holds"  # the checker's verdict
    violated: str = ""  # with status "violated": the property (or failure kind) it names
    message: tuple[str, ...] = ()  # words the violation's message must contain
    check: dict[str, Any] = field(default_factory=dict)
    timed: bool = False  # the invariants hold under the model's timing only (see below)
    crash: str = ""  # live: kill this node's process once it has run 3 events

    def scenario(self, tmp_path: Path, name: str) -> Path:
        doc = {"name": f"conf-{name.replace('_', '-')}", "semantics": "ros", "seed": 1,
               "nodes": self.nodes, "properties": self.properties,
               "live": {"wall_timeout_s": 20, "time_scale": 10.0}}
        if self.check:
            doc["check"] = self.check
        path = tmp_path / f"{name}.yaml"
        path.write_text(yaml.safe_dump(doc, sort_keys=False))
        return path


def node(name: str, cls: str, respawn: bool = False, **params: Any) -> dict[str, Any]:
    entry: dict[str, Any] = {"name": name, "class": M + cls, **({"respawn": True}
                                                                 if respawn else {})}
    if params:
        entry["params"] = params
    return entry


def prop(name: str, kind: str, expr: str | None = None) -> dict[str, Any]:
    return {"name": name, "kind": kind, **({"expr": expr} if expr else {})}


CASES: dict[str, Case] = {
    "pubsub": Case(
        [node("talker", "Talker"), node("listener", "Listener")],
        [prop("in_order", "invariant", "listener.seen == tuple(range(1, listener.count + 1))"),
         prop("all_heard", "eventually", "listener.count == 3")]),
    "priorities": Case(
        [node("sender", "TwoTopics"), node("receiver", "Prioritised")],
        [prop("high_first", "invariant", "receiver.seen in ((), (2,), (2, 1))")],
        timed=True),
    "services_and_timeouts": Case(
        [node("client", "Client"), node("server", "Doubler")],
        [prop("answered", "eventually", "client.answers == (42,) and client.errors == "
                                        "('/absent',)")]),
    "after": Case(
        [node("chain", "Chain")],
        [prop("seven_apart", "invariant", "chain.at == (7, 14, 21)[:len(chain.at)]"),
         prop("args", "invariant", "chain.args == (1, 2, 3)[:len(chain.args)]")]),
    "every": Case(
        [node("ticker", "Ticker")],
        # On the timer's grid from 25: a loaded node that falls a period or more behind
        # skips the missed ticks (Rule 7), so live ticks may be more than a period apart.
        [prop("on_the_grid", "invariant",
              "ticker.at[:1] in ((), (25,)) and all((t - 5) % 20 == 0 for t in ticker.at) "
              "and ticker.at == tuple(sorted(set(ticker.at)))"),
         prop("three", "eventually", "len(ticker.at) == 3")]),
    "qos_depth": Case(  # a burst of 3 into depth 2: the oldest may be dropped, nothing else
        [node("talker", "Talker", burst=3, rounds=1), node("listener", "Shallow")],
        [prop("keeps_the_newest", "invariant",
              "listener.seen in ((), (1,), (1, 2), (1, 2, 3), (2,), (2, 3))"),
         prop("all_heard", "eventually", "listener.count == 3")],
        status="violated", violated="all_heard"),
    "qos_depth_enough": Case(  # depth 2 holds a burst of 2: nothing is ever dropped
        [node("talker", "Talker", burst=2), node("listener", "Shallow")],
        [prop("all_heard", "eventually", "listener.count == 6")]),
    "qos_reliability": Case(  # BEST_EFFORT: every delivery may be lost, so `eventually` fails
        [node("talker", "Talker"), node("listener", "Lossy")],
        [prop("in_order", "invariant",
              "listener.seen == tuple(sorted(set(listener.seen)))"),
         prop("all_heard", "eventually", "listener.count == 3")],
        status="violated", violated="all_heard"),
    "on_start": Case(
        [node("starter", "TwoStarts"), node("greeter", "Greeter")],
        [prop("starts_first", "invariant",
              "starter.order in (('first', 'second'), ('first', 'second', 'hello'))")]),
    "exceptions": Case(
        [node("talker", "Talker"), node("listener", "Fragile"), node("never", "NeverHeard")],
        [prop("rolled_back", "invariant", "2 not in listener.seen and never.count == 0")],
        status="violated", violated="no_failure", message=("listener.on_chat", "two is unlucky")),
    "crash_and_restart": Case(  # the counter may crash once anywhere, and starts afresh
        [node("counter", "Counter", respawn=True), node("boss", "Boss")],
        [prop("counted", "invariant", "0 <= counter <= 5 and 0 <= boss.last <= 5"),
         prop("restart_seen", "invariant", "not boss.done or boss.restarted")],
        check={"faults": {"crash": {"nodes": ["counter"], "max": 1}}}, crash="counter"),
    "liveliness_and_restart": Case(  # the onlooker sees the counter go and come back
        [node("counter", "Counter", respawn=True), node("boss", "Boss"),
         node("onlooker", "Onlooker")],
        [prop("one_crash", "invariant", "onlooker.seen.count(('counter', False)) <= 1"),
         prop("back", "invariant", "onlooker.seen.count(('counter', True)) <= 2")],
        check={"faults": {"crash": {"nodes": ["counter"], "max": 1}}}, crash="counter"),
    "liveliness": Case(  # every node appears at the start, the watcher included
        [node("watcher", "Watcher"), node("quiet", "Quiet")],
        [prop("alive", "invariant", "all(alive for _, alive in watcher.seen)"),
         prop("both", "eventually",
              "sorted(watcher.seen) == [('quiet', True), ('watcher', True)]")]),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_the_checker_answers_as_the_feature_means(name, tmp_path):
    case = CASES[name]
    result = check(case.scenario(tmp_path, name), CheckOptions())
    assert result.status == case.status, result.summary()
    if case.violated:
        assert result.violation is not None and result.violation.property == case.violated
        for word in case.message:
            assert word in result.violation.message, result.violation.message


def launch(scenario: Path, events: Path, crash: str = "") -> str:
    """Run `scenario` live (one process per node over Zenoh) with its event log; with
    `crash`, SIGKILL that node's process once it has run 3 events and every message it
    sent has been handled (the launcher respawns it)."""
    proc = subprocess.Popen([sys.executable, "-m", "twinfleet", "launch", str(scenario),
                             "--record-events", str(events)], cwd=ROOT, env=child_env(),
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True)
    try:
        if crash:
            kill_when_logged(proc.pid, Path(f"{events}.parts"), crash)
        out, _ = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert "shutdown requested by" in out, out[-3000:]
    return out


def _events(part: Path) -> list[str]:
    lines = part.read_text().splitlines() if part.exists() else []
    return [line for line in lines if '"kind":"header"' not in line]


def kill_when_logged(launcher: int, parts: Path, name: str, events: int = 3) -> None:
    """SIGKILL node `name`'s process (a child of `launcher`) once its log in `parts` holds
    `events` events and each of its ticks has been delivered (`boss` logged as many
    deliveries from it). Killed between logging a handler and publishing its message, the
    node would lose that message, which the model's crash does not do: a quiet moment
    (every logged tick delivered, the next one a period away) keeps the test about the
    crash the model has."""
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        ran = len(_events(parts / f"{name}.jsonl"))
        heard = sum(f'"sender":"{name}"' in line and '"kind":"delivery"' in line
                    for line in _events(parts / "boss.jsonl"))
        if ran >= events and heard == ran:
            break
        time.sleep(0.002)  # polling files other processes write: nothing to wait on
    else:
        raise AssertionError(f"{name} logged fewer than {events} delivered events in 30 s")
    (pid,) = [p for p in children(launcher) if f"--node\0{name}\0".encode()
              in Path(f"/proc/{p}/cmdline").read_bytes()]
    os.kill(pid, signal.SIGKILL)


def children(pid: int) -> list[int]:
    """The live child processes of `pid`."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            with contextlib.suppress(OSError, IndexError, ValueError):
                if int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1]) == pid:
                    found.append(int(entry.name))
    return found


@pytest.mark.slow
@pytest.mark.fleet
@pytest.mark.timeout(90)
@pytest.mark.parametrize("name", sorted(CASES))
def test_every_live_event_log_is_a_path_of_the_checker(name, tmp_path):
    case = CASES[name]
    scenario = case.scenario(tmp_path, name)
    events = tmp_path / f"{name}.events.jsonl"
    out = launch(scenario, events, case.crash)
    if case.crash:
        assert f"respawning {case.crash}" in out, out[-3000:]
    result = validate(events, scenario, tolerance_ms=None)
    assert result.ok, result.summary()
    assert result.events > 0
    # Handler priority orders what waits at one fleet millisecond; live, /low may arrive
    # and run a millisecond before /high does, a path of the untimed checker only.
    held = {p["name"] for p in case.properties if p["kind"] == "invariant" and not case.timed}
    assert not [v for v in result.violations if v[1] in held], result.violations


def final_states(path: Path, node_name: str) -> set[Any]:
    """The states of `node_name` in every world with nothing left to run (BFS by hand)."""
    system = System(load(path))
    i = system.index[node_name]
    seen, frontier, finals = set(), [t.world for t in system.initial()], set()
    while frontier:
        world = frontier.pop()
        if world.key in seen:
            continue
        seen.add(world.key)
        nxt = [t.world for t in system.successors(world)]
        if not nxt:
            finals.add(system.decode(i, world.states[i]).seen)
        frontier += nxt
    return finals


def test_keep_last_drops_only_the_oldest_waiting_message(tmp_path):
    # Three messages in one handler into depth 2: the listener keeps up (1, 2, 3), or the
    # oldest is dropped while the other two wait (2, 3) -- never (1, 3) or fewer.
    path = CASES["qos_depth"].scenario(tmp_path, "depth")
    assert final_states(path, "listener") == {(1, 2, 3), (2, 3)}
    enough = CASES["qos_depth_enough"].scenario(tmp_path, "enough")
    assert final_states(enough, "listener") == {(1, 2, 3, 4, 5, 6)}


def test_best_effort_may_lose_any_message(tmp_path):
    path = CASES["qos_reliability"].scenario(tmp_path, "lossy")
    finals = final_states(path, "listener")
    assert (1, 2, 3) in finals and () in finals and (1, 3) in finals and len(finals) == 8


def test_latched_subscriptions_of_nodes_that_may_crash_are_refused_at_load(tmp_path):
    case = Case([node("talker", "Talker"), node("listener", "Latched")],
                check={"faults": {"crash": {"nodes": ["listener"], "max": 1}}})
    with pytest.raises(ScenarioError, match=r"node listener: on_chat \(/chat\) has qos "
                                            r"durability TRANSIENT_LOCAL"):
        check(case.scenario(tmp_path, "latched"), CheckOptions())
    fine = Case([node("talker", "Talker"), node("listener", "Latched")],
                [prop("all_heard", "eventually", "listener.count == 3")])
    assert check(fine.scenario(tmp_path, "latched_ok"), CheckOptions()).status == "holds"
