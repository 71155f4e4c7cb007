"""Helpers of the adversarial tests: scenario files and `twinfleet launch` subprocesses that
are always cleaned up (processes found by the scenario path, which is private to a test)."""

from __future__ import annotations

import contextlib
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import yaml

from tests.support import ROOT, child_env

NODES = "tests.adversarial.verdict_nodes"


def write_scenario(tmp_path: Path, name: str, nodes: list[dict], properties: list[dict],
                   **top: object) -> Path:
    """A scenario file of `nodes` (class names of `NODES` or "module:Class") in `tmp_path`."""
    for node in nodes:
        if ":" not in node["class"]:
            node["class"] = f"{NODES}:{node['class']}"
    doc = {"name": name, "nodes": nodes, "properties": properties, **top}
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def robot_scenario(tmp_path: Path, robots: dict[str, dict]) -> Path:
    """The case study's map server and `robots` (name → start, goal, speed, max_wait_ms)
    on map50, with the properties of c1a."""
    nodes = [{"name": "map_server", "class": "twinfleet.nodes.map_server:MapServer",
              "priority": 1, "params": {"robots": list(robots)}}]
    nodes += [{"name": r, "class": "twinfleet.nodes.robot:Robot", "namespace": f"/{r}",
               "priority": 2 + i, "params": p} for i, (r, p) in enumerate(robots.items())]
    done = " and ".join(f"{r}.done" for r in robots)
    props = [{"name": "no_collision", "kind": "invariant", "expr": "map_server.collisions == 0"},
             {"name": "no_handler_failure", "kind": "no_failure"},
             {"name": "all_arrive", "kind": "eventually", "expr": done}]
    return write_scenario(tmp_path, "robots", nodes, props,
                          params={"map": str(ROOT / "twinfleet" / "maps" / "map50.yaml"),
                                  "scan_rate_ms": 100},
                          live={"report": "twinfleet.nodes.report:report_for"})


def launch_command(scenario: Path, *args: str) -> list[str]:
    """The command line of `twinfleet launch SCENARIO ARGS`."""
    return [sys.executable, "-m", "twinfleet", "launch", str(scenario), *args]


@contextlib.contextmanager
def launched(scenario: Path, *args: str) -> Iterator[subprocess.Popen[str]]:
    """`twinfleet launch` running in the background (stdout piped, stderr merged); every
    process of the scenario is killed on the way out."""
    from tests.integration.itest_support import kill_all, spawned_by

    proc = subprocess.Popen(launch_command(scenario, *args), stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, env=child_env(), cwd=ROOT)
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait(timeout=10)
        if proc.stdout is not None:
            proc.stdout.close()
        kill_all(spawned_by(proc.pid))


def wait_for_line(proc: subprocess.Popen[str], text: str, seen: list[str]) -> bool:
    """Read `proc`'s output into `seen` until a line contains `text` (False: it ended)."""
    assert proc.stdout is not None
    for line in proc.stdout:
        seen.append(line)
        if text in line:
            return True
    return False


def run_launch(scenario: Path, *args: str, timeout: float = 60.0) -> subprocess.CompletedProcess[str]:
    """`twinfleet launch SCENARIO ARGS` to its end (stderr merged into stdout)."""
    from tests.integration.itest_support import kill_all, spawned_by

    command = launch_command(scenario, *args)
    with subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                          env=child_env(), cwd=ROOT) as proc:
        try:
            out, _ = proc.communicate(timeout=timeout)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait(timeout=10)
            kill_all(spawned_by(proc.pid))
    return subprocess.CompletedProcess(command, proc.returncode, out)


def expect(run: subprocess.CompletedProcess[str], code: int, *texts: str) -> str:
    """Assert that a launch ended with exit `code` and printed every one of `texts`;
    return its output."""
    out = run.stdout
    assert run.returncode == code, out[-3000:]
    for text in texts:
        assert text in out, (text, out[-3000:])
    return out
