"""The default install (no rosbags): twinfleet.interfaces imports, the command line runs, and a
node that needs a ROS 2 definition gets one line saying what to install."""

from __future__ import annotations

import subprocess
import sys

import pytest

from tests.support import ROOT

pytestmark = pytest.mark.timeout(60)

WITHOUT_ROSBAGS = "import sys; sys.modules['rosbags'] = None\n"  # an import of it then fails


def _run(code: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-P", "-c", WITHOUT_ROSBAGS + code],
                          capture_output=True, text=True, cwd=ROOT, timeout=60)


@pytest.mark.parametrize("package", ["geometry_msgs", "nav_msgs", "std_srvs"])
def test_a_definition_without_rosbags_is_one_line_naming_the_extra(package):
    kind = "srv" if package == "std_srvs" else "msg"
    proc = _run("from twinfleet.interfaces import InterfaceError, load_interface\n"
                "try:\n"
                f"    module = load_interface({package!r}, {kind!r})\n"
                "    getattr(module, module.__all__[0])\n"
                "except InterfaceError as exc:\n"
                "    print(exc)\n")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == ("ROS 2 message definitions need rosbags, which is not "
                                   "installed: pip install 'twinfleet[rclpy]'")


def test_native_types_with_any_name_load_without_rosbags():
    proc = _run("from twinfleet.interfaces.guard import install\n"
                "from twinfleet import message\n"
                "install()\n"
                "@message('geometry_msgs/Twist')\n"
                "class Flat:\n"
                "    x: float = 0.0\n"
                "print('loaded')\n")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "loaded"
