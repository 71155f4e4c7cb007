"""`launch` refuses a property that reads a field no node state has before it starts anything."""

from __future__ import annotations

import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from itest_support import child_env

pytestmark = pytest.mark.timeout(60)

# Every object of this node writes the id of the process that built it: the launcher builds
# one to look the property's fields up; a node process would build another.
NODE = '''
import os
from dataclasses import dataclass
from pathlib import Path

from twinfleet import Context, Node, every


@dataclass
class Battery:
    battery: int = 100
    charging: bool = False


class Robot(Node):
    def initial_state(self) -> Battery:
        with Path(os.environ["BUILT_BY"]).open("a") as log:
            log.write(f"{os.getpid()}\\n")
        return Battery()

    @every(100)
    def drain(self, ctx: Context) -> None:
        self.state.battery -= 1
'''

SCENARIO = '''
name: prop_field
nodes:
  - {name: r1, class: "robots:Robot"}
  - {name: r2, class: "robots:Robot"}
properties:
  - {name: charged, kind: invariant, expr: "r1.batery > 10 and r2.battery > 10"}
live: {wall_timeout_s: 8}
'''


def test_a_misspelt_property_field_stops_launch_before_any_process(tmp_path: Path) -> None:
    (tmp_path / "robots.py").write_text(textwrap.dedent(NODE))
    (tmp_path / "prop_field.yaml").write_text(SCENARIO)
    built = tmp_path / "built.txt"
    env = {**child_env(tmp_path), "BUILT_BY": str(built)}
    begun = time.monotonic()
    proc = subprocess.Popen([sys.executable, "-m", "twinfleet", "launch", "prop_field.yaml",
                             "--timeout", "8"], cwd=tmp_path, env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    out, err = proc.communicate(timeout=30)
    elapsed = time.monotonic() - begun
    assert proc.returncode == 2, (out, err)
    assert elapsed < 3.0, elapsed
    assert err.strip() == ("twinfleet launch: prop_field.yaml: property 'charged': "
                           "r1.batery: the state of r1 (Battery) has no field 'batery'; its "
                           "fields: battery, charging")
    assert out == ""
    builders = set(built.read_text().split())
    assert builders == {str(proc.pid)}, builders  # only the launcher built a node
