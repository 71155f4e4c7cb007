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
from pathlib import Path
from typing import Any

from tests.support import child_env

PROGRAMS = Path(__file__).resolve().parent / "programs"


def real_rclpy(program: str, *args: str, timeout_s: float = 60.0) -> dict[str, Any]:
    """Run ``programs/<program>.py ARGS`` under real rclpy; what it printed after RESULT."""
    env = child_env()
    env.update(RMW_IMPLEMENTATION="rmw_fastrtps_cpp", ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               ROS_DOMAIN_ID=str(random.randint(1, 100)))
    proc = subprocess.run([sys.executable, str(PROGRAMS / f"{program}.py"), *args],
                          capture_output=True, text=True, timeout=timeout_s, env=env,
                          cwd=PROGRAMS, check=False)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    assert proc.returncode == 0 and lines, f"exit {proc.returncode}\n{proc.stdout}\n{proc.stderr}"
    return json.loads(lines[-1].removeprefix("RESULT "))  # type: ignore[no-any-return]


def twinfleet(*args: str, timeout_s: float = 120.0) -> subprocess.CompletedProcess[str]:
    """Run ``python -m twinfleet ARGS`` in the programs' folder."""
    return subprocess.run([sys.executable, "-m", "twinfleet", *args], capture_output=True,
                          text=True, timeout=timeout_s, env=child_env(), cwd=PROGRAMS,
                          check=False)


def launch(scenario: str, *args: str, timeout_s: float = 20.0) -> subprocess.CompletedProcess[str]:
    """Launch a program's scenario live until its eventually properties hold or the timeout."""
    return twinfleet("launch", scenario, "--until-settled", "--timeout", str(timeout_s), *args,
                     timeout_s=timeout_s + 60.0)


def in_process_env() -> None:
    """Let in-process checks import the programs as a scenario in their folder does."""
    if str(PROGRAMS) not in sys.path:
        sys.path.append(str(PROGRAMS))
    os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
