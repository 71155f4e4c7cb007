"""`twinfleet validate`: event logs of live runs against the checker's transition relation.

Fast tests build logs from checker paths (what a perfectly timed run would
record) and tamper with them; the slow ones record a real multi-process C1a
run with `twinfleet launch --record-events` and validate it.
"""

from __future__ import annotations

import asyncio
import contextlib
import io
import json
import os
import signal
import subprocess
import sys
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import pytest
import yaml

from twinfleet import Context, Node, String, handler, on_start, subscribe
from twinfleet.agreement import validate as v
from twinfleet.agreement.events import EVENTS_FORMAT, EventLogFile, LiveEvent, load_events
from twinfleet.agreement.live_replay import plan
from twinfleet.checker.choices import PrefixChooser
from twinfleet.checker.driver import CheckOptions, check, load
from twinfleet.checker.system import System
from twinfleet.checker.transition import RunEvent
from twinfleet.runtime.contract.snapshot import snapshot
from twinfleet.runtime.core.eventlog import EventLog, payload_digest, state_digest
from twinfleet.runtime.host.clock import ManualClock
from twinfleet.runtime.host.node_host import NodeHost
from twinfleet.runtime.host.transport import LoopbackBus, LoopbackTransport

ROOT = Path(__file__).resolve().parents[2]
HEADON = ROOT / "twinfleet" / "launch" / "headon.yaml"
C1A = ROOT / "twinfleet" / "launch" / "c1a.yaml"


# ------------------------------------------------------------------ helpers


def write_log(path: Path, records: list[dict[str, Any]], nodes: list[str]) -> Path:
    """An event log file as the launcher writes it."""
    lines = [{"format": EVENTS_FORMAT, "kind": "fleet", "nodes": nodes, "restarts": {}}]
    lines += [{"format": EVENTS_FORMAT, "kind": "header", "node": n} for n in nodes]
    path.write_text("".join(json.dumps(r) + "\n" for r in [*lines, *records]))
    return path


def trace_records(trace_path: Path) -> tuple[list[dict[str, Any]], list[str]]:
    """The event records a perfectly timed live run of a trace would log (live t = logical t)."""
    p = plan(trace_path)
    counters: dict[str, int] = {}
    records = []
    for planned in [*p.starts, *p.steps]:
        g = planned.grant
        i = counters.get(planned.node, 0)
        counters[planned.node] = i + 1
        records.append({"node": planned.node, "i": i, "t": g.t, "kind": g.kind,
                        "handler": g.handler, "sender": g.sender, "args": g.args,
                        "summary": planned.summary, "choices": list(g.choices),
                        "options": list(planned.options or ()), "digest": planned.digest})
    return records, [cfg.name for cfg in p.scenario.nodes]


@pytest.fixture(scope="module")
def headon_trace(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("headon") / "headon.trace.json"
    # unreduced: the shortest trace (a reduced BFS trace is shortest in the reduced graph only)
    result = check(HEADON, CheckOptions(trace_out=str(out), reduction="none"))
    assert result.violation is not None and result.violation.property == "no_collision"
    return out


def index_of(records: list[dict[str, Any]], **match: Any) -> int:
    return next(k for k, r in enumerate(records) if all(r.get(a) == b for a, b in match.items()))


# ------------------------------------------------------------------ logs of checker paths


def test_a_checker_path_logged_as_events_validates_strictly(headon_trace, tmp_path):
    records, nodes = trace_records(headon_trace)
    log = write_log(tmp_path / "events.jsonl", records, nodes)
    result = v.validate(log, HEADON, tolerance_ms=0)
    assert result.ok, result.summary()
    assert result.explained == result.events == len(records) - len(nodes)
    assert result.max_ahead_ms == 0
    # the trace ends in the collision: the validator sees the invariant fail at the last step
    assert result.violations[0][:2] == (result.events, "no_collision")


def test_a_changed_choice_is_the_first_unexplained_step(headon_trace, tmp_path):
    records, nodes = trace_records(headon_trace)
    k = next(k for k, r in enumerate(records) if r["choices"])
    assert records[k]["options"] == [3]
    chosen = records[k]["choices"][0]
    records[k]["choices"] = [5]  # no such option
    result = v.validate(write_log(tmp_path / "e.jsonl", records, nodes), HEADON)
    assert result.failure is not None
    assert result.failure.reason == v.CHOICES
    assert result.failure.step == k - len(nodes) + 1
    assert (result.failure.event.node, result.failure.event.index) == (records[k]["node"],
                                                                       records[k]["i"])
    # another valid option: the checker takes it, and the node's state no longer matches
    records[k]["choices"] = [(chosen + 1) % 3]
    result = v.validate(write_log(tmp_path / "e2.jsonl", records, nodes), HEADON)
    assert result.failure is not None and result.failure.reason == v.STATE
    assert result.failure.step == k - len(nodes) + 1


def test_a_changed_state_digest_is_reported_with_the_checker_state(headon_trace, tmp_path):
    records, nodes = trace_records(headon_trace)
    k = index_of(records, node="map_server", handler="on_pose")
    records[k]["digest"] = "0" * 24
    result = v.validate(write_log(tmp_path / "e.jsonl", records, nodes), HEADON)
    f = result.failure
    assert f is not None and f.reason == v.STATE
    assert (f.event.node, f.event.handler, f.event.index) == ("map_server", "on_pose",
                                                              records[k]["i"])
    assert "MapServerState(" in f.expected and f.seen == "digest " + "0" * 24
    assert result.failure.step == k - len(nodes) + 1
    assert result.explained >= k - len(nodes)  # other nodes' events at the same time may follow


def test_a_dropped_message_leaves_its_stream_blocked(headon_trace, tmp_path):
    records, nodes = trace_records(headon_trace)
    scans = [k for k, r in enumerate(records) if r["node"] == "r2" and r["handler"] == "on_scan"]
    # a scan that changes nothing (same state before and after) and is followed by another scan
    k = next(k for a, k, b in zip(scans, scans[1:], scans[2:], strict=False)
             if records[a]["digest"] == records[k]["digest"] and _next_of(records, k) == b)
    dropped = records.pop(k)
    result = v.validate(write_log(tmp_path / "e.jsonl", records, nodes), HEADON, tolerance_ms=None)
    f = result.failure
    assert f is not None and f.reason == v.ORDER
    assert (f.event.node, f.event.handler) == ("r2", "on_scan")
    assert "r2.on_scan" in f.expected and "first (same stream)" in f.expected
    # identical scans after the gap are explained by the pending ones, shifted by one; the
    # first scan with new content shows that one is missing
    between = [r for r in records if r["node"] == "r2" and r["handler"] == "on_scan"
               and dropped["i"] < r["i"] < f.event.index]
    assert between and all(r["args"] == dropped["args"] for r in between)
    assert f.event.args != dropped["args"]


def _next_of(records: list[dict[str, Any]], k: int) -> int:
    node = records[k]["node"]
    return next(j for j in range(k + 1, len(records)) if records[j]["node"] == node)


def test_a_different_message_is_model_drift(headon_trace, tmp_path):
    records, nodes = trace_records(headon_trace)
    k = index_of(records, node="map_server", handler="on_pose")
    records[k]["args"] = payload_digest(("something else",))
    result = v.validate(write_log(tmp_path / "e.jsonl", records, nodes), HEADON)
    assert result.failure is not None and result.failure.reason == v.PAYLOAD
    assert "RobotPose(" in result.failure.expected


def test_a_message_before_on_start_is_a_startup_difference(headon_trace, tmp_path):
    records, nodes = trace_records(headon_trace)
    start = index_of(records, node="r2", kind="start")
    scan = index_of(records, node="r2", handler="on_scan")
    records[start]["i"], records[scan]["i"] = records[scan]["i"], records[start]["i"]
    result = v.validate(write_log(tmp_path / "e.jsonl", records, nodes), HEADON)
    assert result.failure is not None and result.failure.reason == v.START
    assert result.failure.step == 0


# ------------------------------------------------------------------ timing rules


@dataclass
class TickState:
    ticks: int = 0


@dataclass(frozen=True)
class TickParams:
    period_ms: int = 30
    first_ms: int = -1  # the first tick (default: one period after start)


class Ticker(Node):
    """Counts its own ticks; two of them never interact, so only timing orders them."""

    Params = TickParams

    def initial_state(self) -> TickState:
        return TickState()

    @on_start
    def start(self, ctx: Context) -> None:
        p = self.params
        ctx.after(p.first_ms if p.first_ms >= 0 else p.period_ms, self.tick)

    @handler()
    def tick(self, ctx: Context) -> None:
        self.state.ticks += 1
        ctx.after(self.params.period_ms, self.tick)


def tickers(tmp_path: Path, first_a: int = -1) -> Path:
    doc = {"name": "tickers", "nodes": [
        {"name": "a", "class": "test_validate:Ticker",
         "params": {"period_ms": 30, "first_ms": first_a}},
        {"name": "b", "class": "test_validate:Ticker", "params": {"period_ms": 50}}]}
    path = tmp_path / "tickers.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def walk_records(scenario: Path, steps: int) -> tuple[list[dict[str, Any]], list[str]]:
    """Records of the path that always takes the first enabled event."""
    system = System(load(scenario))
    t = system.initial_world()
    records, counters = [], {}

    def emit(node: int, ev_t: int, kind: str, method: str, digest: str) -> None:
        name = system.names[node]
        counters[name] = counters.get(name, -1) + 1
        records.append({"node": name, "i": counters[name], "t": ev_t, "kind": kind,
                        "handler": method, "sender": name, "args": payload_digest(()),
                        "choices": [], "options": [], "digest": digest})

    for i in range(len(system.names)):
        emit(i, 0, "start", "start", state_digest(t.world.states[i]))
    world = t.world
    for _ in range(steps):
        t = system.step(world, system.actions(world)[0], PrefixChooser())
        ev, world = t.event, t.world
        emit(ev.target, ev.due, "timer", ev.method, state_digest(world.states[ev.target]))
    return records, list(system.names)


def test_timing_rules_strict_tolerance_and_untimed(tmp_path):
    scenario = tickers(tmp_path)
    records, nodes = walk_records(scenario, 8)
    # a@30, b@50, a@60, a@90, b@100, a@120, a@150, b@150 (model times): b@50 ran at live t=20,
    # more than the 5 ms window before a@30
    k = index_of(records, node="b", t=50)
    records[k]["t"] = 20
    records.sort(key=lambda r: r["t"])
    log = write_log(tmp_path / "e.jsonl", records, nodes)
    strict = v.validate(log, scenario, tolerance_ms=0)
    assert strict.failure is not None and strict.failure.reason == v.TIMING
    assert strict.failure.event.node == "b" and strict.failure.step == 1
    assert "t*=30 ms" in strict.failure.expected and "due at t=50 ms" in strict.failure.expected
    assert not v.validate(log, scenario, tolerance_ms=19).ok
    wide = v.validate(log, scenario, tolerance_ms=20)
    assert wide.ok and (wide.max_ahead_ms, wide.ahead_steps) == (20, 1)
    untimed = v.validate(log, scenario, tolerance_ms=None)
    assert untimed.ok and untimed.max_ahead_ms == 20


def test_running_ahead_of_a_model_clock_at_zero_is_measured(tmp_path):
    # a@0, a@30, b@50 (model); live, b@50 ran first, while the model's clock was still at 0:
    # 50 ms ahead (t* = 0 is a time like any other)
    scenario = tickers(tmp_path, first_a=0)
    records, nodes = walk_records(scenario, 3)
    records[index_of(records, node="a", t=0, kind="timer")]["t"] = 1
    records[index_of(records, node="b", t=50)]["t"] = 0
    records.sort(key=lambda r: r["t"])
    log = write_log(tmp_path / "e.jsonl", records, nodes)
    untimed = v.validate(log, scenario, tolerance_ms=None)
    assert untimed.ok and untimed.max_ahead_ms == 50, untimed.summary()
    assert v.validate(log, scenario, tolerance_ms=50).ok


def test_equal_time_events_of_different_nodes_within_the_window_interleave(tmp_path):
    scenario = tickers(tmp_path)
    records, nodes = walk_records(scenario, 8)
    # a@150 and b@150: the checker allows either order; so does the live order b, a
    a, b = index_of(records, node="a", t=150), index_of(records, node="b", t=150)
    records[a], records[b] = records[b], records[a]
    result = v.validate(write_log(tmp_path / "e.jsonl", records, nodes), scenario)
    assert result.ok, result.summary()


def test_cli_exit_codes_and_json(headon_trace, tmp_path):
    from twinfleet.cli import main

    records, nodes = trace_records(headon_trace)
    good = write_log(tmp_path / "good.jsonl", records, nodes)
    records[-1]["digest"] = "f" * 24
    bad = write_log(tmp_path / "bad.jsonl", records, nodes)
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["validate", str(good), str(HEADON)]) == 0
        assert main(["validate", str(bad), str(HEADON), "--tolerance-ms", "0"]) == 1
        assert main(["validate", str(bad), str(HEADON), "--json"]) == 1
    text = out.getvalue()
    assert "VALID" in text and "strict timing (the checker's exact rules): every step" in text
    record = json.loads(text[text.index("{"):])
    assert record["failure"]["reason"] == v.STATE and record["strict"]["ok"] is False
    assert main(["validate", str(tmp_path / "missing.jsonl"), str(HEADON)]) == 2


# ------------------------------------------------------------------ the host's event log


@dataclass
class Heard:
    seen: tuple[str, ...] = ()


class Talker(Node):
    def initial_state(self) -> Heard:
        return Heard()

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.publish("/chat", String(ctx.choose(["hi", "ho"])))


class Listener(Node):
    def initial_state(self) -> Heard:
        return Heard()

    @on_start
    def start(self, ctx: Context) -> None:
        self.state.seen = (*self.state.seen, "start")

    @subscribe("/chat")
    def on_chat(self, ctx: Context, msg: String) -> None:
        self.state.seen = (*self.state.seen, msg.data)


def test_host_logs_each_dispatch_and_runs_on_start_before_earlier_messages(tmp_path):
    async def body() -> tuple[Heard, list[LiveEvent]]:
        bus, clock = LoopbackBus(), ManualClock(start_ms=40)
        log = EventLog(str(tmp_path / "listener.jsonl"), node="listener")
        hosts = []
        # the listener waits for a peer that never comes: the talker's message arrives first
        waiting = {"wait_for": ("talker", "ghost"), "ready_timeout_s": 0.2, "events": log}
        for node, kw in ((Listener("listener"), waiting), (Talker("talker"), {})):
            transport = LoopbackTransport(bus)
            await transport.open()
            hosts.append(NodeHost(node, transport, clock, seed=3, fleet="f", out=io.StringIO(),
                                  **kw))
        listener_task = asyncio.create_task(hosts[0].run())
        talker_task = asyncio.create_task(hosts[1].run())
        await asyncio.sleep(0.4)
        for h in hosts:
            h.stop()
        await asyncio.gather(listener_task, talker_task)
        log.close()
        return hosts[0].node.state, load_events(tmp_path / "listener.jsonl").events

    state, events = asyncio.run(asyncio.wait_for(body(), 10))
    assert state.seen[0] == "start"  # the talker's message arrived first, but waited
    start, chat = events
    assert (start.kind, start.handler, start.index, start.t) == ("start", "start", 0, 40)
    assert (chat.kind, chat.handler, chat.sender, chat.topic, chat.seq, chat.stamp) == (
        "delivery", "on_chat", "talker", "/chat", 1, 40)
    assert chat.args == payload_digest((String(state.seen[1]),))
    assert chat.digest == state_digest(snapshot(state))


def test_host_logs_choices_with_their_option_counts(tmp_path):
    async def body() -> list[LiveEvent]:
        transport = LoopbackTransport(LoopbackBus())
        await transport.open()
        log = EventLog(str(tmp_path / "talker.jsonl"), node="talker")
        host = NodeHost(Talker("talker"), transport, ManualClock(), seed=3, fleet="f",
                        out=io.StringIO(), events=log)
        task = asyncio.create_task(host.run())
        await asyncio.sleep(0.01)
        host.stop()
        await task
        log.close()
        return load_events(tmp_path / "talker.jsonl").events

    (start,) = asyncio.run(asyncio.wait_for(body(), 10))
    assert start.options == (2,) and start.choices[0] in (0, 1)


# ------------------------------------------------------------------ a real live run


def _children_of(pid: int) -> list[int]:
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            with contextlib.suppress(OSError, IndexError, ValueError):
                stat = (entry / "stat").read_text()
                if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                    found.append(int(entry.name))
    return found


@pytest.fixture(scope="module")
def c1a_events(tmp_path_factory: pytest.TempPathFactory) -> EventLogFile:
    """A live C1a run (six processes over Zenoh, time scale 5: at 10 a robot can fall behind
    its queue while the other test worker runs CPU-bound checks) with its event log."""
    path = tmp_path_factory.mktemp("c1a") / "c1a.events.jsonl"
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen([sys.executable, "-m", "twinfleet", "launch", str(C1A),
                             "--time-scale", "5", "--timeout", "60", "--record-events",
                             str(path)], cwd=ROOT, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, start_new_session=True)
    try:
        out, _ = proc.communicate(timeout=100)
    finally:
        nodes = _children_of(proc.pid)
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        for pid in nodes:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
    assert "shutdown requested by map_server: all robots arrived" in out, out[-3000:]
    return load_events(path)


@pytest.mark.slow
@pytest.mark.timeout(150)
def test_live_c1a_run_is_a_path_of_the_checker(c1a_events):
    result = v.validate(c1a_events, C1A, tolerance_ms=None)
    assert result.ok, result.summary()
    assert result.events > 3000
    assert not result.violations  # no collision, no livelock on the live path
    # timing: the same run under the checker's exact rules stops at its first timing difference
    strict = v.validate(c1a_events, C1A, tolerance_ms=0, max_backtracks=2_000)
    assert not strict.ok and strict.failure is not None
    assert strict.failure.reason == v.TIMING, strict.summary()
    # ... and the gap the untimed path reports is a tolerance that explains the run
    tolerant = v.validate(c1a_events, C1A, tolerance_ms=max(1, result.max_ahead_ms))
    assert tolerant.ok, tolerant.summary()


@pytest.mark.slow
@pytest.mark.timeout(150)
def test_tampered_live_c1a_logs_show_the_first_unexplained_step(c1a_events):
    events = list(c1a_events.events)
    k = next(k for k, e in enumerate(events) if e.node == "r3" and e.handler == "on_path")
    bad = replace(events[k], digest="0" * 24)
    result = v.validate(_with(c1a_events, {k: bad}), C1A, tolerance_ms=None)
    assert result.failure is not None and result.failure.reason == v.STATE
    assert result.failure.event == bad
    bad = replace(events[k], choices=(1,), options=(2,))
    result = v.validate(_with(c1a_events, {k: bad}), C1A, tolerance_ms=None)
    assert result.failure is not None and result.failure.reason == v.CHOICES
    assert result.failure.event == bad
    # dropping the map server's first pose report from r3: its next one cannot come first
    k = next(k for k, e in enumerate(events)
             if e.node == "map_server" and e.handler == "on_pose" and e.sender == "r3")
    result = v.validate(_with(c1a_events, {k: None}), C1A, tolerance_ms=None)
    f = result.failure
    assert f is not None and f.event is not None and f.event.node == "map_server"
    assert f.reason in (v.ORDER, v.STATE), result.summary()
    assert f.event.index == events[k].index + 1


def _with(log: EventLogFile, changes: dict[int, LiveEvent | None]) -> EventLogFile:
    events = [changes.get(k, e) for k, e in enumerate(log.events)]
    return EventLogFile(log.path, log.header, log.node_headers, [e for e in events if e])


# ------------------------------------------------------------------ latency and faults


@dataclass
class HeardState:
    ticked: bool = False
    heard: bool = False


class Sender(Node):
    """Publishes /x from a timer at t=0."""

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.after(0, self.send)

    @handler()
    def send(self, ctx: Context) -> None:
        ctx.publish("/x", String("x"))


class EarlySender(Node):
    """Publishes /x from its @on_start."""

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.publish("/x", String("x"))


class LateListener(Node):
    """Ticks at t=1 and records whether /x came first."""

    def initial_state(self) -> HeardState:
        return HeardState()

    @on_start
    def start(self, ctx: Context) -> None:
        ctx.after(1, self.tick)

    @handler()
    def tick(self, ctx: Context) -> None:
        self.state.ticked = True

    @subscribe("/x")
    def on_x(self, ctx: Context, msg: String) -> None:
        self.state.heard = True


def one_invariant(tmp_path: Path, name: str, nodes: dict[str, str], invariant: str,
                  expr: str, check_settings: dict[str, Any]) -> Path:
    """A scenario of `nodes` (name: class) with one invariant, written to `tmp_path`."""
    doc = {"name": name, "nodes": [{"name": n, "class": c} for n, c in nodes.items()],
           "properties": [{"name": invariant, "kind": "invariant", "expr": expr}],
           "check": check_settings}
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def sender_listener(tmp_path: Path, name: str, sender: str = "Sender",
                    **check_settings: Any) -> Path:
    return one_invariant(tmp_path, name, {"s": f"test_validate:{sender}",
                                          "l": "test_validate:LateListener"},
                         "heard_first", "l.heard or not l.ticked", check_settings)


def test_latency_branches_explain_a_late_delivery_strictly(tmp_path):
    late = sender_listener(tmp_path, "late", latency={"/x": [0, 2]})
    trace = tmp_path / "late.trace.json"
    assert check(late, CheckOptions(trace_out=str(trace))).status == "violated"
    records, names = trace_records(trace)  # live: the listener ticked at t=1, /x not yet there
    assert [(r["node"], r["handler"], r["t"]) for r in records if r["kind"] != "start"] == [
        ("s", "send", 0), ("l", "tick", 1)]
    log = write_log(tmp_path / "e.jsonl", records, names)
    strict = v.validate(log, late, tolerance_ms=0)
    assert strict.ok, strict.summary()
    assert [name for _, name, _ in strict.violations] == ["heard_first"]
    # without the latency branches, /x is due at t=0, before the tick: a timing difference
    plain = v.validate(log, sender_listener(tmp_path, "plain"), tolerance_ms=0)
    assert not plain.ok and plain.failure.reason == v.TIMING, plain.summary()


def test_latency_of_a_start_handler_message_is_searched_too(tmp_path):
    late = sender_listener(tmp_path, "early", sender="EarlySender", latency={"/x": [0, 2]})
    trace = tmp_path / "early.trace.json"
    assert check(late, CheckOptions(trace_out=str(trace))).status == "violated"
    records, names = trace_records(trace)  # /x, sent by s's @on_start, came after l's tick
    assert [(r["node"], r["handler"]) for r in records if r["kind"] != "start"] == [("l", "tick")]
    log = write_log(tmp_path / "e.jsonl", records, names)
    strict = v.validate(log, late, tolerance_ms=0)
    assert strict.ok and [p for _, p, _ in strict.violations] == ["heard_first"], strict.summary()
    plain = v.validate(log, sender_listener(tmp_path, "plain", sender="EarlySender"),
                       tolerance_ms=0)
    assert not plain.ok and plain.failure.reason == v.TIMING, plain.summary()


def test_crash_faults_and_drops_and_duplicates_are_searched(tmp_path):
    from tests.checker.helpers import node, scenario

    nodes = [node("ping", "Ping", rounds=3), node("pong", "Pong")]
    done = [{"name": "unfinished", "kind": "invariant", "expr": "pong.received < 3"}]
    trace = tmp_path / "ok.trace.json"
    check(scenario(tmp_path, nodes, name="ok", properties=done), CheckOptions(trace_out=str(trace)))
    records, names = trace_records(trace)  # the whole fault-free exchange
    log = write_log(tmp_path / "e.jsonl", records, names)
    faulty = scenario(tmp_path, nodes, name="faulty",
                      faults={"drop": ["/pong"], "duplicate": ["/ping"]})
    result = v.validate(log, faulty, tolerance_ms=0)
    assert result.ok, result.summary()
    crashing = scenario(tmp_path, nodes, name="crashing", faults={"crash": {"nodes": ["pong"]}})
    assert v.validate(log, crashing).ok  # a crash may happen, it need not
    # A live restart is the checker's crash: refused where the scenario has no crash fault,
    # and where it has one but nothing is pending any more (no crash action then).
    k = index_of(records, node="pong")
    crashed = [*records[:k], {"node": "pong", "i": 0, "t": records[k]["t"], "kind": "crash",
                              "handler": "", "sender": "", "args": "", "digest": ""},
               *records[k:]]
    for r in crashed[k + 1:]:
        if r["node"] == "pong":
            r["i"] += 1
    log2 = write_log(tmp_path / "e2.jsonl", crashed, names)
    refused = v.validate(log2, faulty)
    assert refused.failure is not None and refused.failure.reason == v.OUTSIDE
    allowed = v.validate(log2, crashing)  # the crash is taken: whatever fails later, not it
    assert allowed.failure is None or allowed.failure.reason != v.OUTSIDE, allowed.summary()
    assert allowed.explained > refused.explained


class Hearer(Node):
    """Notes that /x came; sends nothing."""

    def initial_state(self) -> HeardState:
        return HeardState()

    @subscribe("/x")
    def on_x(self, ctx: Context, msg: String) -> None:
        self.state.heard = True


def test_a_run_cut_off_by_a_crash_is_the_models_crash_before_it(tmp_path):
    """A node logs a run, then publishes: killed in between, its log holds a run whose
    outputs nobody received and whose state died with it: the checker's crash before it."""
    doc = {"name": "hear", "nodes": [{"name": "s", "class": "test_validate:EarlySender"},
                                     {"name": "l", "class": "test_validate:Hearer"}],
           "properties": [{"name": "deaf", "kind": "invariant", "expr": "not l.heard"}]}
    (tmp_path / "hear.yaml").write_text(yaml.safe_dump(doc))
    trace = tmp_path / "hear.trace.json"
    assert check(tmp_path / "hear.yaml", CheckOptions(trace_out=str(trace))).status == "violated"
    records, names = trace_records(trace)  # s starts and sends /x, l hears it
    assert [(r["node"], r["handler"]) for r in records if r["kind"] != "start"] == [("l", "on_x")]
    crash = {"node": "l", "i": 1, "t": records[-1]["t"] + 5, "kind": "crash", "handler": "",
             "sender": "", "args": "", "digest": ""}
    log = write_log(tmp_path / "cut.jsonl", [*records, crash], names)
    crashing = tmp_path / "crashing.yaml"
    crashing.write_text(yaml.safe_dump({**doc, "name": "crashing",
                                        "check": {"faults": {"crash": {"nodes": ["l"]}}}}))
    result = v.validate(log, crashing, tolerance_ms=0)
    # Taken as run, on_x leaves nothing pending, and a crash then is no action of the model;
    # taken as cut off, the crash comes first and discards the /x it was handling.
    assert result.ok, result.summary()
    assert result.explained == 2 and not result.violations, result.summary()
    assert v.validate(log, tmp_path / "hear.yaml").failure.reason == v.OUTSIDE


def test_a_path_only_if_timing_is_ignored_is_not_valid_and_its_violation_comes_first(
        tmp_path, capsys):
    from twinfleet.cli import main

    doc = yaml.safe_load(tickers(tmp_path).read_text())
    doc["properties"] = [{"name": "a_first", "kind": "invariant", "expr": "b.ticks <= a.ticks"}]
    scenario = tmp_path / "tickers.yaml"
    scenario.write_text(yaml.safe_dump(doc))
    records, nodes = walk_records(scenario, 8)
    records[index_of(records, node="b", t=50)]["t"] = 20  # b's first tick before a's (a@30)
    records.sort(key=lambda r: r["t"])
    log = write_log(tmp_path / "e.jsonl", records, nodes)
    assert main(["validate", str(log), str(scenario)]) == 3  # untimed: a path; exact: not
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("OUTSIDE THE MODEL: property a_first at step 1 violated on a "
                             "path only if timing is ignored"), out[0]
    assert main(["validate", str(log), str(scenario), "--tolerance-ms", "20", "--json"]) == 3
    assert json.loads(capsys.readouterr().out)["verdict"].startswith("OUTSIDE THE MODEL")
    in_order = write_log(tmp_path / "exact.jsonl", walk_records(scenario, 8)[0], nodes)
    assert main(["validate", str(in_order), str(scenario)]) == 0
    assert capsys.readouterr().out.startswith("VALID: the live run is a path of the "
                                              "checker's exact model")
    capsys.readouterr()
    assert main(["validate", str(in_order), str(scenario), "a.period_ms:=45"]) == 3  # applied
    assert main(["validate", str(in_order), str(scenario), "a.perod_ms:=31"]) == 2
    assert "did you mean 'period_ms'?" in capsys.readouterr().err


def ticker(tmp_path: Path, name: str, **check_settings: Any) -> Path:
    """The conformance ticker (every 20 ms from 25, its first three tick times kept)."""
    return one_invariant(tmp_path, name, {"ticker": "tests.conformance.systems:Ticker"},
                         "on_the_period", "ticker.at == (25, 45, 65)[:len(ticker.at)]",
                         check_settings)


def test_a_run_that_skipped_missed_ticks_is_a_path_of_the_untimed_checker(tmp_path):
    # A live ticker whose tick due at 45 was taken 40-45 ms late: it skipped the ticks at
    # 65 and 85 and ticked next at 105 (Rule 7). Its log, made from the checker's own step with
    # that branch (a node that stores its tick times: a search merges such worlds).
    system = System(load(ticker(tmp_path, "late", timer_lateness=[0, 45])))
    (world,) = [t.world for t in system.initial()]
    records = []
    for i, branch in enumerate((0, 1, 0)):
        due = world.events[0].due
        world = system.step(world, RunEvent(0), PrefixChooser((branch,))).world
        records.append({"node": "ticker", "i": i, "t": due, "due": due, "kind": "periodic",
                        "handler": "tick", "sender": "ticker", "args": payload_digest(()),
                        "digest": state_digest(world.states[0])})
    assert [r["due"] for r in records] == [25, 45, 105]
    log = write_log(tmp_path / "e.jsonl", records, ["ticker"])
    plain = ticker(tmp_path, "plain")  # a scenario that says nothing of timer lateness
    assert v.skipped_lateness(System(load(plain)), load_events(log)) == 40
    untimed = v.validate(log, plain, tolerance_ms=None)
    assert untimed.ok, untimed.summary()
    assert [name for _, name, _ in untimed.violations] == ["on_the_period"]
    # Strictly, the model's timers are on time: the skip is not its path.
    assert not v.validate(log, plain, tolerance_ms=0).ok
