"""Safe property expressions (docs/design.md §5): a scenario's properties are checked at
load against a small language, so code in them never runs, with one line naming the
property (exit 2) for `check` and `launch` alike; and `--max-time` holds inside a slow one."""

from __future__ import annotations

import subprocess
import sys
import time

import pytest

from tests.adversarial.fleets import write_scenario
from tests.support import ROOT, child_env
from twinfleet.runtime.scenario.spec import ScenarioError, load_scenario

pytestmark = pytest.mark.timeout(60)

COUNTER = [{"name": "counter", "class": "Counter"}]


def _scenario(tmp_path, expr: str, kind: str = "invariant"):
    return write_scenario(tmp_path, "props", [dict(n) for n in COUNTER],
                          [{"name": "sneaky", "kind": kind, "expr": expr}],
                          check={"max_states": 200})


def _twinfleet(*args: str, timeout: float = 30.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "twinfleet", *args], capture_output=True,
                          text=True, timeout=timeout, env=child_env(), cwd=ROOT, check=False)


@pytest.mark.parametrize("command", ["check", "launch"])
def test_the_import_probe_is_refused_at_load_and_never_runs(tmp_path, command):
    marker = tmp_path / "pwned"
    path = _scenario(tmp_path, f"__import__('os').system('touch {marker}') == 0")
    run = _twinfleet(command, str(path))
    assert run.returncode == 2, run.stdout + run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1, run.stderr
    assert "properties[0].expr: property 'sneaky':" in lines[0]
    assert "'__import__'" in lines[0]
    assert not marker.exists()
    assert "fleet" not in run.stdout  # nothing was launched


@pytest.mark.parametrize(("expr", "said"), [
    ("counter.__class__", "'__class__'"),
    ("().__class__.__bases__[0].__subclasses__()", "is not allowed (attributes starting"),
    ("open('/etc/passwd') is None", "'open'"),
    ("eval('1') == 1", "'eval'"),
    ("'{0.__class__}'.format(counter) != ''", ".format\" is not allowed"),
    ("(lambda: 1)() == 1", "lambda"),
    ("counter.count.bit_length() < 3", "'counter.count.bit_length'"),
    ("len([x for x in (y for y in ()).gi_frame]) > 0", "'gi_frame'"),
    ("sorted([1], key=counter) == [1]", "key="),
    ("max([1], **{}) == 1", "'**'"),
    ("(n := 3) > 2", "':='"),
    ("f'{counter}' != ''", "f-string"),
    ("robot.count > 0", "unknown name 'robot'"),
    ("_secret > 0", "'_secret'"),
])
def test_outside_the_language_is_refused_naming_the_property(tmp_path, expr, said):
    with pytest.raises(ScenarioError) as caught:
        load_scenario(_scenario(tmp_path, expr))
    text = str(caught.value)
    assert "property 'sneaky'" in text and said in text, text
    assert "\n" not in text


@pytest.mark.parametrize("expr", [
    "counter.count >= 0 and not counter.count < 0",
    "all(v >= 0 for v in (counter.count, abs(-1)))",
    "sum([c for c in range(3)]) == 3 and max(1, 2) == 2 and min([3, 4]) == 3",
    "len(nodes) == 1 and len({k: 1 for k in nodes}) == 1",
    "nodes['counter'].count == counter.count",
    "all(s.count >= 0 for s in nodes.values()) and nodes.get('x', 1) == 1",
    "(1, 2, 2).count(2) == 2 and len(list(nodes.items())) == 1",
    "sorted((3, 1), key=abs, reverse=True)[0] == 3",
    "now >= 0 and (counter.count if counter.count else 0) >= 0",
])
def test_the_language_is_enough_for_properties_over_states(tmp_path, expr):
    path = _scenario(tmp_path, expr)
    run = _twinfleet("check", str(path), "--max-states", "200")
    # The counter counts for ever: the search ends at its state limit, every state checked.
    assert run.returncode == 2, run.stdout + run.stderr
    assert "verdict: UNKNOWN: max-states 200 reached" in run.stdout, run.stdout + run.stderr


@pytest.mark.slow
def test_max_time_holds_inside_a_slow_property(tmp_path):
    path = _scenario(tmp_path, "sum(range(10**12)) > 0")
    started = time.monotonic()
    run = _twinfleet("check", str(path), "--max-time", "1", timeout=30)
    elapsed = time.monotonic() - started
    assert run.returncode == 2, run.stdout + run.stderr  # no answer
    assert "max-time 1 s reached while evaluating the property" in run.stdout + run.stderr
    assert "properties[0] (sneaky)" in run.stdout
    assert elapsed < 15  # without the limit inside evaluation: hours


def _search_reason(tmp_path, expr: str) -> str:
    from twinfleet.checker import Limits, PropertySet, Search, System
    from twinfleet.checker.driver import load

    tmp_path.mkdir()
    scen = load(_scenario(tmp_path, expr))
    props = PropertySet.from_scenario(scen)
    return Search(System(scen, properties=props), props, Limits(max_time_s=0.2)).run("bfs").reason


@pytest.mark.parametrize("expr", ["sum(range(10**12)) > 0",
                                  "all(True for _ in range(10**12) for _ in range(9))",
                                  "len([a for a in range(10**6) for b in range(10**6)]) > 0"])
def test_max_time_holds_in_a_worker_thread_with_the_same_message(tmp_path, expr):
    import threading

    main = _search_reason(tmp_path / "main", expr)
    seen: list[str] = []
    worker = threading.Thread(target=lambda: seen.append(_search_reason(tmp_path / "t", expr)),
                              daemon=True)
    started = time.monotonic()
    worker.start()
    worker.join(timeout=20)
    assert not worker.is_alive(), "the property ran past its limit in a worker thread"
    assert time.monotonic() - started < 10
    assert [r.replace('/t/', '/main/') for r in seen] == [main]
    assert "max-time 0.2 s reached while evaluating the property" in main
    assert "(sneaky)" in main


def test_time_limit_leaves_a_tracer_in_place_and_nests():
    import sys as _sys

    from twinfleet.runtime.scenario.property_eval import Overtime, parse_expression, time_limit

    expr = parse_expression("sum(range(10**12)) > 0", [], "here")
    calls: list[str] = []

    def tracer(frame, event, arg):
        calls.append(event)

    _sys.settrace(tracer)
    try:
        with time_limit(60), time_limit(0.05), pytest.raises(Overtime, match="here: 'sum"):
            expr.evaluate({})
        assert _sys.gettrace() is tracer
    finally:
        _sys.settrace(None)
    assert parse_expression("1 + 1 == 2", [], "x").evaluate({})  # no limit: plain eval
