"""Bad files, fuzzed: maps, scenarios and traces give one clear error, never a traceback.

In-process, every bad input raises only the module's own error type (MapError,
ScenarioError, or the CLI's exit code 2 with a message); a few CLI runs check
that the user sees that message and no traceback.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from twinfleet.cli import main
from twinfleet.nodes.mapfile import MapError, load_map
from twinfleet.runtime.scenario.spec import ScenarioError, load_scenario

ROOT = Path(__file__).resolve().parents[2]
FUZZ = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
GOOD_SCENARIO = yaml.safe_load((ROOT / "twinfleet" / "launch" / "headon.yaml").read_text())
GOOD_SCENARIO["params"]["map"] = str(ROOT / "twinfleet" / "maps" / "corridor12.yaml")


def pgm_header(magic: bytes, w: int, h: int, maxval: int) -> bytes:
    return magic + b"\n# fuzz\n" + f"{w} {h}\n{maxval}\n".encode()


pgm_bytes = st.one_of(
    st.binary(max_size=300),
    st.builds(lambda m, w, h, mv, body: pgm_header(m, w, h, mv) + body,
              st.sampled_from([b"P5", b"P2", b"P6", b"P", b""]), st.integers(-2, 20),
              st.integers(-2, 20), st.integers(-1, 70000), st.binary(max_size=500)),
)
map_yaml = st.fixed_dictionaries(
    {}, optional={
        "image": st.sampled_from(["m.pgm", "missing.pgm", "", 3]),
        "resolution": st.one_of(st.floats(allow_nan=True), st.integers(-1, 2), st.text(max_size=3)),
        "origin": st.one_of(st.lists(st.floats(allow_nan=False, width=32), max_size=4), st.text(max_size=3)),
        "negate": st.one_of(st.integers(-1, 2), st.text(max_size=2)),
        "occupied_thresh": st.floats(-1, 2),
        "free_thresh": st.floats(-1, 2),
    })


@FUZZ
@given(pgm=pgm_bytes, doc=map_yaml)
def test_fuzzed_map_files_fail_with_a_map_error_naming_the_file(tmp_path, pgm, doc):
    (tmp_path / "m.pgm").write_bytes(pgm)
    path = tmp_path / "m.yaml"
    path.write_text(yaml.safe_dump(doc))
    try:
        occ = load_map(path)
    except MapError as exc:
        assert str(tmp_path) in str(exc)
    else:
        assert occ.gray.ndim == 2


yaml_values = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(-3, 60), st.floats(allow_nan=False),
              st.text(max_size=6)),
    lambda inner: st.one_of(st.lists(inner, max_size=3),
                            st.dictionaries(st.text(max_size=6), inner, max_size=3)),
    max_leaves=8,
)


def _set(doc: dict, path: list, value) -> dict:
    target = doc
    for key in path[:-1]:
        target = target[key]
    target[path[-1]] = value
    return doc


PATHS = [["name"], ["params", "profile"], ["params", "map"], ["semantics"], ["seed"], ["params"], ["nodes"], ["properties"],
         ["check"], ["live"], ["nodes", 0, "class"], ["nodes", 1, "params"],
         ["nodes", 1, "params", "start"], ["nodes", 1, "params", "speed"], ["nodes", 2, "name"],
         ["nodes", 0, "params", "robots"], ["properties", 0], ["properties", 0, "expr"]]


@FUZZ
@given(path=st.sampled_from(PATHS), value=yaml_values)
def test_fuzzed_scenarios_fail_with_a_scenario_error(tmp_path, path, value):
    doc = _set(json.loads(json.dumps(GOOD_SCENARIO)), path, value)
    file = tmp_path / "s.yaml"
    file.write_text(yaml.safe_dump(doc))
    try:
        load_scenario(file)
    except ScenarioError as exc:
        assert str(file) in str(exc)


@FUZZ
@given(st.binary(max_size=200))
def test_garbage_scenario_bytes_fail_with_a_scenario_error(tmp_path, raw):
    file = tmp_path / "s.yaml"
    file.write_bytes(raw)
    with pytest.raises(ScenarioError):
        load_scenario(file)


@pytest.fixture(scope="module")
def headon_trace(tmp_path_factory):
    from twinfleet.checker.driver import CheckOptions, check

    out = tmp_path_factory.mktemp("trace") / "headon.json"
    check(ROOT / "twinfleet" / "launch" / "headon.yaml", CheckOptions(trace_out=str(out)))
    return out.read_text()  # text: hypothesis prints the arguments of a failing example


TRACE_PATHS = [["format"], ["scenario"], ["semantics"], ["params"], ["steps"], ["initial"],
               ["initial", "choices"], ["initial", "digest"], ["steps", 0], ["steps", 3, "event"],
               ["steps", 3, "choices"], ["steps", 5, "digest"], ["property"], ["latency"]]


@pytest.mark.slow
@FUZZ
@given(path=st.sampled_from(TRACE_PATHS), value=yaml_values)
def test_fuzzed_traces_make_replay_and_render_exit_2_with_a_message(tmp_path, capsys, headon_trace,
                                                                   path, value):
    doc = _set(json.loads(headon_trace), path, value)
    file = tmp_path / "t.json"
    file.write_text(json.dumps(doc))
    code = main(["replay", str(file)])
    said = capsys.readouterr()
    assert code in (1, 2)  # 1 only if the change did not matter (the violation is confirmed)
    if code == 2:
        assert str(file) in said.err or "NOT confirmed" in said.out
    assert main(["render", str(file), "-o", str(tmp_path / "x.png")]) in (0, 2)


@pytest.mark.parametrize("argv", [
    ["check", "{dir}/bad.yaml"], ["launch", "{dir}/bad.yaml"], ["replay", "{dir}/bad.json"],
    ["render", "{dir}/bad.json", "-o", "{dir}/x.png"], ["replay", "{dir}/missing.json"],
])
def test_the_user_sees_one_message_and_no_traceback(tmp_path, argv):
    (tmp_path / "bad.yaml").write_text("nodes: [{name: r1, class: 'twinfleet.nodes.robot:Robot', params: {speed: fast}}]\n")
    (tmp_path / "bad.json").write_text('{"format": "twinfleet-trace/1", "steps": 3}')
    args = [a.format(dir=tmp_path) for a in argv]
    proc = subprocess.run([sys.executable, "-m", "twinfleet", *args], capture_output=True, text=True,
                          timeout=60, cwd=ROOT, check=False)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stderr
    assert str(tmp_path) in proc.stderr
