"""A user's mistake gets a diagnosis, never a crash (docs/design.md §3).

Each case is a node from tests/checker/mistakes.py that breaks the node contract the
way users' first nodes do. `twinfleet check` must end with exit code 4 and one line
naming the node, the handler and the fix, with no traceback, in every run.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from tests.checker.tpc import tpc_scenario
from twinfleet.checker import check
from twinfleet.checker.driver import CheckOptions
from twinfleet.cli import main

pytestmark = pytest.mark.timeout(60)

M = "tests.checker.mistakes"
# (class, companion class or None, node named, handler named, words of the diagnosis)
CASES = [
    ("RandomInStart", "Hello", "n1", "begin (@on_start)", "random.random()"),
    ("GlobalCounter", None, "n1", "tick (@handler)", "it changed tests.checker.mistakes.COUNTER"),
    ("ClassCounter", None, "n1", "tick (@handler)", "it changed ClassCounter.seen"),
    ("HiddenTally", None, "n1", "bump (@handler)", "it changed HiddenTally.tally"),
    ("WallClock", None, "n1", "stamp (@handler)", "time.time()"),
    ("BoundRandom", None, "n1", "roll (@handler)", "the new node state differs"),
    ("DateNow", None, "n1", "begin (@on_start)", "the new node state differs"),
    ("Sleeper", None, "n1", "begin (@on_start)", "time.sleep()"),
    ("UuidCaller", "UuidServer", "server", "ident (@service)", "uuid.uuid4()"),
    ("Urandom", None, "n1", "begin (@on_start)", "os.urandom()"),
    ("NumpyRandom", None, "n1", "begin (@on_start)", "numpy.random.random()"),
    ("LambdaTimer", None, "n1", "begin (@on_start)", "never a lambda"),
    ("UnregisteredMessage", None, "n1", "begin (@on_start)",
     "needs a message, got Dock(slot=1); fix: register the class with @message("),
    ("UnhashableArgs", None, "n1", "begin (@on_start)", "must be hashable"),
    ("ObjectInState", None, "n1", "begin (@on_start)", "cannot be encoded"),
    ("FunctionInState", "Pinger", "n1", "on_hello (@subscribe)", "cannot be encoded"),
    ("AttributeCounter", None, "n1", "tick (@handler)", "self.ticks"),
    ("BadInitialState", None, "n1", "initial_state", "initial state cannot be encoded"),
]


def scenario_file(tmp_path: Path, cls: str, companion: str | None) -> Path:
    nodes = [{"name": "n1", "class": f"{M}:{cls}"}]
    if companion is not None:
        nodes.append({"name": "server" if cls == "UuidCaller" else "other",
                      "class": f"{M}:{companion}"})
    path = tmp_path / f"{cls}.yaml"
    path.write_text(yaml.safe_dump({"name": cls.lower(), "nodes": nodes}))
    return path


@pytest.mark.parametrize(("cls", "companion", "node", "handler", "words"), CASES,
                         ids=[c[0] for c in CASES])
def test_a_mistake_is_one_line_naming_node_and_handler_exit_4(tmp_path, capsys, cls, companion,
                                                              node, handler, words):
    code = main(["check", str(scenario_file(tmp_path, cls, companion)), "--quiet"])
    out, err = capsys.readouterr()
    assert code == 4, err
    (line,) = [x for x in err.splitlines() if not x.startswith("warning:")]
    assert line.startswith("twinfleet check: contract breach")
    assert f"node {node}, handler {handler}" in line
    assert words in line and "fix:" in line
    assert "Traceback" not in out + err and out == ""


def test_the_randomness_mistake_is_found_in_20_of_20_runs(tmp_path, capsys):
    path = scenario_file(tmp_path, "RandomInStart", "Hello")
    codes = [main(["check", str(path), "--quiet"]) for _ in range(20)]
    assert codes == [4] * 20
    lines = [x for x in capsys.readouterr().err.splitlines() if "contract breach" in x]
    assert len(lines) == 20 and all("node n1, handler begin (@on_start)" in x for x in lines)


def test_without_the_checks_the_counter_fools_the_search(tmp_path):
    # What the default checks are for: unverified, a hidden counter gives a verdict.
    path = scenario_file(tmp_path, "AttributeCounter", None)
    assert check(path, CheckOptions(verify=False, trace_out=None)).status == "holds"
    assert check(path, CheckOptions(trace_out=None)).exit_code == 4


def test_the_lint_names_the_risky_imports_with_file_and_line(tmp_path, capsys):
    main(["check", str(scenario_file(tmp_path, "RandomInStart", "Hello")), "--quiet"])
    warnings = [x for x in capsys.readouterr().err.splitlines() if x.startswith("warning:")]
    source = Path(__file__).with_name("mistakes.py")
    lines = source.read_text().splitlines()
    for module in ("random", "time", "datetime", "uuid", "os.urandom", "numpy.random"):
        hits = [w for w in warnings if f"imports {module}:" in w]
        assert hits, module
        for hit in hits:
            where = hit.split(": ")[1]
            assert where.startswith(f"{source}:")
            assert module.split(".")[-1] in lines[int(where.rsplit(":", 1)[1]) - 1]


def test_with_the_checks_off_a_path_that_does_not_run_again_is_a_breach_not_a_traceback(
        tmp_path, capsys):
    from tests.checker import mistakes

    mistakes.TICKS[0] = 0
    path = tmp_path / "leaky.yaml"
    path.write_text(yaml.safe_dump({
        "name": "leaky", "nodes": [{"name": "n1", "class": f"{M}:LeakyTicker"}],
        "properties": [{"name": "small", "kind": "invariant", "expr": "n1.value < 3"}]}))
    assert main(["check", str(path), "--quiet", "--no-contract-checks"]) == 4
    err = capsys.readouterr().err
    assert "does not run again" in err and "--no-contract-checks" in err
    assert "Traceback" not in err
    mistakes.TICKS[0] = 0
    assert main(["check", str(path), "--quiet"]) == 4  # checked: named at once
    assert "node n1, handler tick (@handler)" in capsys.readouterr().err


def test_the_probe_sees_only_the_handlers_thread_and_puts_everything_back():
    import random
    import threading
    import time

    from twinfleet.checker.diagnosis import EnvironmentProbe

    originals = (time.time, time.monotonic, random.random, random.choice)
    probe = EnvironmentProbe()
    with probe:
        other = threading.Thread(target=time.monotonic)
        other.start()
        other.join()
        time.time()
        random.choice([1, 2])
        time.time()
    assert probe.calls == ["time.time", "random.choice"]  # in order, once each
    assert (time.time, time.monotonic, random.random, random.choice) == originals


def test_the_console_script_reports_it_in_its_own_process(tmp_path):
    import subprocess
    import sys

    from tests.support import ROOT, child_env

    path = scenario_file(tmp_path, "RandomInStart", "Hello")
    run = subprocess.run([sys.executable, "-m", "twinfleet", "check", str(path), "--quiet"],
                         cwd=ROOT, env=child_env(), capture_output=True, text=True, timeout=50)
    assert run.returncode == 4, run.stderr
    assert "node n1, handler begin (@on_start): it called random.random()" in run.stderr
    assert "Traceback" not in run.stderr and run.stdout == ""


def test_a_sound_handler_is_run_twice_and_its_second_run_builds_no_events(monkeypatch, tmp_path):
    # Every fresh handler run is verified by a second run from the same state; when the
    # handler keeps the contract, that second run compares the new state, effects and reply
    # with the first's (`Runner._same_again`) instead of building and hashing its events
    # again: every verified run takes the full path once.
    from twinfleet.checker.runner import Runner

    full = 0
    exec_ = Runner._exec

    def counting(self, *args):
        nonlocal full
        full += 1
        return exec_(self, *args)

    monkeypatch.setattr(Runner, "_exec", counting)
    result = check(tpc_scenario(tmp_path), CheckOptions(reduction="none"))
    assert result.status == "holds" and result.handler_runs > 50  # kept runs reused: 58
    assert result.handler_runs == 2 * full
