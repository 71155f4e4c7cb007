"""What a trace hides, no more: node code is hashed into it, so that `replay` of edited
code says so first; drops, duplicates and crashes are shown by `trace show`
(issue 37, finding 8)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tests.support import child_env
from twinfleet.cli import main
from twinfleet.runtime.tools.view.sequence_chart import Text, layout
from twinfleet.runtime.tools.view.viewstate import trace_document

pytestmark = pytest.mark.timeout(120)

NODE = '''
from dataclasses import dataclass
from twinfleet import Context, Node, every


@dataclass
class Count:
    n: int = 0


class Tally(Node):
    def initial_state(self) -> Count:
        return Count()

    @every(10)
    def tick(self, ctx: Context) -> None:
        self.state.n = (self.state.n + STEP) % 6
'''


@pytest.mark.slow  # two subprocesses
def test_replay_says_first_that_a_nodes_code_changed_since_the_trace(tmp_path, capsys):
    (tmp_path / "honest_tally.py").write_text("STEP = 1\n" + NODE)
    path = tmp_path / "tally.yaml"
    path.write_text("name: tally\nnodes:\n  - {name: t, class: 'honest_tally:Tally'}\n"
                    "properties:\n  - {name: small, kind: invariant, expr: 't.n < 3'}\n")
    trace = tmp_path / "tally.trace.json"
    assert main(["check", str(path), "--quiet", "--trace-out", str(trace)]) == 1
    assert json.loads(trace.read_text())["node_code"]["t"]
    (tmp_path / "honest_tally.py").write_text("STEP = 2\n" + NODE)  # t.n: 2, 4: violated later
    replayed = subprocess.run([sys.executable, "-m", "twinfleet", "replay", str(trace)],
                              capture_output=True, text=True, env=child_env(), cwd=tmp_path,
                              timeout=60, check=False)
    assert replayed.returncode == 2, replayed
    first = replayed.stderr.splitlines()[0]
    assert first == ("twinfleet replay: warning: node t's code changed since the trace "
                     f"({tmp_path / 'honest_tally.py'})"), replayed.stderr
    assert "node t's code changed since the trace" in replayed.stdout + replayed.stderr.split(
        "\n", 1)[1]  # and the verdict names it as the cause
    live = subprocess.run([sys.executable, "-m", "twinfleet", "replay", str(trace), "--live"],
                          capture_output=True, text=True, env=child_env(), cwd=tmp_path,
                          timeout=60, check=False)  # refused before any fleet starts
    assert live.returncode == 2, live
    assert live.stderr.startswith("twinfleet replay --live: warning: node t's code changed"), \
        live.stderr
    capsys.readouterr()


def test_trace_show_shows_drops_duplicates_and_crashes(tmp_path, capsys):
    from tests.checker.helpers import node, scenario

    ping_pong = [node("ping", "Ping", rounds=3), node("pong", "Pong")]
    finished = [{"name": "finishes", "kind": "deadlock",
                 "expr": "ping.sent == 3 and pong.received == 3"}]
    bounded = [{"name": "bounded", "kind": "invariant",
                "expr": "ping.sent - pong.received <= 1"}]
    cases = [("drop", finished, {"drop": ["/pong"]}, "FAULT /pong to ping: dropped"),
             ("crash", bounded, {"crash": {"nodes": ["pong"]}}, "pong crashed and restarted")]
    for name, props, faults, says in cases:
        path = scenario(tmp_path, ping_pong, name=name, properties=props, faults=faults)
        trace = tmp_path / f"{name}.trace.json"
        assert main(["check", str(path), "--quiet", "--trace-out", str(trace)]) == 1
        capsys.readouterr()
        assert main(["trace", "show", str(trace)]) == 0
        out = capsys.readouterr().out
        assert says in out, out
        assert main(["trace", "show", str(trace), "--json"]) == 0
        walked = json.loads(capsys.readouterr().out)
        fault = says.removeprefix("FAULT ")
        assert any(fault in f for s in walked["steps"] for f in s["faults"])
        chart = layout(walked)  # what `render --chart` draws (PNG and SVG alike)
        assert any(isinstance(x, Text) and fault in x.text for x in chart.shapes)
        viewed = trace_document(trace)  # what the viewer's trace mode shows
        assert any(fault in f for s in viewed["steps"] for f in s["faults"])


def test_a_lasso_shows_the_message_dropped_on_its_cycle(tmp_path, capsys):
    path = tmp_path / "retry.yaml"
    path.write_text("name: retry\nnodes:\n"
                    "  - {name: a, class: 'tests.checker.retry_nodes:Asker'}\n"
                    "  - {name: b, class: 'tests.checker.retry_nodes:Answerer'}\n"
                    "properties:\n  - {name: answered, kind: eventually, expr: a.answered}\n"
                    "check:\n  faults: {drop: [/req]}\n")
    trace = tmp_path / "retry.trace.json"
    assert main(["check", str(path), "--quiet", "--trace-out", str(trace)]) == 1
    capsys.readouterr()
    assert main(["trace", "show", str(trace)]) == 0
    out = capsys.readouterr().out.splitlines()
    cycle = out.index("      (the cycle starts at the initial world)")
    assert "        FAULT /req to b: dropped" in out[cycle:], out


def test_the_progress_line_says_when_the_reduction_restarts(tmp_path, capsys):
    from tests.checker.tpc import tpc_scenario
    from twinfleet.checker.commands import _progress
    from twinfleet.checker.driver import load
    from twinfleet.checker.outcome import Limits
    from twinfleet.checker.properties import PropertySet
    from twinfleet.checker.reduction import plan
    from twinfleet.checker.search import Search
    from twinfleet.checker.system import System

    scenario = load(tpc_scenario(tmp_path, latency=(0, 2)))
    props = PropertySet.from_scenario(scenario)
    system = System(scenario, properties=props)
    reduction, _ = plan(system, props, "bfs", None)
    seen = []
    Search(system, props, Limits(), progress=seen.append, progress_interval=0,
           reduction=reduction).run("bfs")
    before = next(k for k, s in enumerate(seen) if s.restarts)
    assert seen[before].states < seen[before - 1].states  # the counts went back...
    _progress(seen[before])
    assert "(restart 1: the reduction learned a send and searches again from scratch" \
        in capsys.readouterr().err  # ...and the line says why


def test_the_map_render_gives_a_fault_its_frame_and_caption():
    from twinfleet.checker.driver import load
    from twinfleet.checker.system import System
    from twinfleet.checker.trace import to_json_value
    from twinfleet.nodes.render import trace_views
    from twinfleet.runtime.scenario.examples import shipped_scenarios

    scenario = load(shipped_scenarios()["c1a"])
    system = System(scenario)
    world = system.initial_world().world
    initial = {n: to_json_value(s) for n, s in system.states_of(world).items()}
    steps = [{"index": 1, "time": 5, "node": "r1", "handler": "on_scan", "changed": {},
              "faults": ["/r1/scan to r1: dropped"]},
             {"index": 2, "time": 9, "node": "r2", "handler": "tick", "changed": {}}]
    views = trace_views(scenario, {"initial": {"states": initial}, "steps": steps,
                                   "message": "m"})
    assert len(views) == 3  # the start, the step with a fault (nothing moved), the last
    assert "FAULT /r1/scan to r1: dropped" in views[1].caption
