"""Running a conformance program under real rclpy, under twinfleet live and in the checker.

Real rclpy (Jazzy, Fast DDS) runs in a subprocess with discovery kept on this host and a
domain of its own per run, so that two test sessions never see each other's nodes; the
program's `main()` (programs/oracle_main.py) prints ``RESULT <json>``.
"""

from __future__ import annotations

import json
import os
import random
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from tests.support import child_env

PROGRAMS = Path(__file__).resolve().parent / "programs"


def _ros_env(domain: int) -> dict[str, str]:
    env = child_env()
    env.update(RMW_IMPLEMENTATION="rmw_fastrtps_cpp", ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               ROS_DOMAIN_ID=str(domain))
    return env


def _result(returncode: int, stdout: str, stderr: str) -> dict[str, Any]:
    lines = [ln for ln in stdout.splitlines() if ln.startswith("RESULT ")]
    assert returncode == 0 and lines, f"exit {returncode}\n{stdout}\n{stderr}"
    return json.loads(lines[-1].removeprefix("RESULT "))  # type: ignore[no-any-return]


def real_rclpy(program: str, *args: str, timeout_s: float = 60.0,
               domain: int | None = None) -> dict[str, Any]:
    """Run ``programs/<program>.py ARGS`` under real rclpy; what it printed after RESULT."""
    env = _ros_env(domain or random.randint(1, 100))
    proc = subprocess.run([sys.executable, str(PROGRAMS / f"{program}.py"), *args],
                          capture_output=True, text=True, timeout=timeout_s, env=env,
                          cwd=PROGRAMS, check=False)
    return _result(proc.returncode, proc.stdout, proc.stderr)


class Background:
    """A real-rclpy program running beside the test (`real_rclpy_background`)."""

    def __init__(self, proc: subprocess.Popen[str], domain: int) -> None:
        self.proc, self.domain = proc, domain

    def result(self, timeout_s: float = 60.0) -> dict[str, Any]:
        """Wait for the program's end; what it printed after RESULT."""
        stdout, stderr = self.proc.communicate(timeout=timeout_s)
        return _result(self.proc.returncode, stdout, stderr)


@contextmanager
def real_rclpy_background(program: str, *args: str) -> Iterator[Background]:
    """Start ``programs/<program>.py ARGS`` under real rclpy; stopped if still running at
    the end of the block's caller's test (killed, never left behind)."""
    domain = random.randint(1, 100)
    proc = subprocess.Popen([sys.executable, str(PROGRAMS / f"{program}.py"), *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=_ros_env(domain), cwd=PROGRAMS)
    try:
        yield Background(proc, domain)
    finally:
        if proc.poll() is None:
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def twinfleet(*args: str, timeout_s: float = 120.0) -> subprocess.CompletedProcess[str]:
    """Run ``python -m twinfleet ARGS`` in the programs' folder."""
    return subprocess.run([sys.executable, "-m", "twinfleet", *args], capture_output=True,
                          text=True, timeout=timeout_s, env=child_env(), cwd=PROGRAMS,
                          check=False)


def launch(scenario: str, *args: str, timeout_s: float = 20.0) -> subprocess.CompletedProcess[str]:
    """Launch a program's scenario live until its eventually properties hold or the timeout."""
    return twinfleet("launch", scenario, "--until-settled", "--timeout", str(timeout_s), *args,
                     timeout_s=timeout_s + 60.0)


@contextmanager
def running_fleet(scenario: str, timeout_s: float = 30.0,
                  *args: str) -> Iterator[subprocess.Popen[str]]:
    """`twinfleet launch SCENARIO ARGS` in the background (its output on the process's
    stdout, merged); stopped at the end of the block, killed if it will not stop."""
    fleet = subprocess.Popen([sys.executable, "-m", "twinfleet", "launch", scenario,
                              "--timeout", str(timeout_s), *args], cwd=PROGRAMS, env=child_env(),
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        yield fleet
    finally:
        if fleet.poll() is None:
            fleet.terminate()
            try:
                fleet.wait(timeout=30)
            except subprocess.TimeoutExpired:
                fleet.kill()
                fleet.wait()


def wait_for_line(fleet: subprocess.Popen[str], text: str) -> list[str]:
    """Read the fleet's output up to the first line holding `text`; the lines read."""
    assert fleet.stdout is not None
    seen = []
    for line in fleet.stdout:
        seen.append(line)
        if text in line:
            return seen
    raise AssertionError(f"the fleet ended before printing {text!r}:\n{''.join(seen)}")


def in_process_env() -> None:
    """Let in-process checks import the programs as a scenario in their folder does."""
    if str(PROGRAMS) not in sys.path:
        sys.path.append(str(PROGRAMS))
    os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
