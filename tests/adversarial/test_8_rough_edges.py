"""Failure 8: rough edges.

Before: speed inf, a node class whose import raises, a 10,000-level nested YAML
list and `live.report: os:abort` ended in tracebacks with exit 1; 10,000 robots
were validated for 20-30 s before an error, and nothing capped the node count
(a launch started them all); checkpoints were pickles, which only a module
docstring said. Now each is one line and exit 2, the cap (`live.max_nodes`)
is checked before any node, and `--checkpoint` says what a checkpoint is.
"""

from __future__ import annotations

import subprocess
import sys
import time

import pytest

from tests.support import ROOT, child_env

pytestmark = pytest.mark.timeout(120)

ROBOT = ('{{name: r{i}, class: "twinfleet.nodes.robot:Robot", namespace: /r{i}, '
         'params: {{start: [5, {i}], goal: [45, {i}], speed: {speed}, max_wait_ms: 1500}}}}')


def scenario(tmp_path, name: str, *, robots: int = 1, speed: str = "0.5", server: str =
             "twinfleet.nodes.map_server:MapServer", live: str = "{wall_timeout_s: 5}") -> str:
    nodes = "\n".join(f"- {ROBOT.format(i=i, speed=speed)}" for i in range(1, robots + 1))
    text = (f"name: {name}\nparams: {{map: {ROOT}/twinfleet/maps/map50.yaml}}\nnodes:\n"
            f"- {{name: map_server, class: \"{server}\", params: {{robots: "
            f"[{', '.join(f'r{i}' for i in range(1, robots + 1))}]}}}}\n{nodes}\nlive: {live}\n")
    path = tmp_path / f"{name}.yaml"
    path.write_text(text)
    return str(path)


def one_line_exit_2(*args: str, timeout: float = 60.0) -> str:
    result = subprocess.run([sys.executable, "-m", "twinfleet", *args], capture_output=True,
                            text=True, timeout=timeout, env=child_env(), cwd=ROOT, check=False)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2, (result.returncode, result.stdout[-2000:], result.stderr)
    assert len(lines) == 1 and "Traceback" not in result.stdout + result.stderr, result.stderr
    assert "unexpected" not in lines[0], lines[0]  # a named check, not the last-resort handler
    assert "[r1]" not in result.stdout  # no node process was started
    return lines[0]


def test_infinite_speed(tmp_path) -> None:
    line = one_line_exit_2("launch", scenario(tmp_path, "inf", speed=".inf"))
    assert "params.speed: expected a finite number, got inf" in line


def test_a_node_module_that_raises_on_import(tmp_path) -> None:
    (tmp_path / "boom.py").write_text("raise RuntimeError('import-time failure')\n")
    line = one_line_exit_2("launch", scenario(tmp_path, "boom", server="boom:MapServer"))
    assert "importing 'boom'" in line and "RuntimeError: import-time failure" in line


def test_yaml_nested_ten_thousand_levels(tmp_path) -> None:
    path = tmp_path / "deep.yaml"
    path.write_text("name: deep\nnodes: " + "[" * 10_000 + "]" * 10_000 + "\n")
    assert "nested too deeply" in one_line_exit_2("launch", str(path))


def test_a_report_that_is_a_builtin(tmp_path) -> None:
    line = one_line_exit_2("launch", scenario(tmp_path, "abort", live="{report: 'os:abort'}"))
    assert "live.report: os:abort" in line and "not a report factory" in line


def test_ten_thousand_robots_fail_fast_and_the_cap_is_configurable(tmp_path) -> None:
    started = time.monotonic()
    # `check`, not `launch`: were the cap ever lost, this must not start 10,000 processes
    line = one_line_exit_2("check", scenario(tmp_path, "many", robots=10_000))
    assert time.monotonic() - started < 20
    assert "10001 nodes, more than live.max_nodes = 100" in line
    small = scenario(tmp_path, "capped", robots=2, live="{max_nodes: 2}")
    assert "3 nodes, more than live.max_nodes = 2" in one_line_exit_2("launch", small)


def test_checkpoint_help_says_it_is_a_pickle_trusted_like_code() -> None:
    result = subprocess.run([sys.executable, "-m", "twinfleet", "check", "--help"],
                            capture_output=True, text=True, timeout=30, env=child_env(),
                            cwd=ROOT, check=False)
    text = " ".join(result.stdout.split())
    assert "A checkpoint is a Python pickle" in text and "trusted like code" in text
