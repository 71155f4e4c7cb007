"""The default install (no rosbags): twinfleet.interfaces imports, the command line runs, and a
node that needs a ROS 2 definition gets one line saying what to install."""

from __future__ import annotations

import pytest

from tests.interfaces.fresh import run_python

pytestmark = pytest.mark.timeout(60)

WITHOUT_ROSBAGS = "import sys; sys.modules['rosbags'] = None\n"  # an import of it then fails


def _run(code: str) -> tuple[int, str, str]:
    """Exit code, output and errors of `code` run where rosbags cannot be imported."""
    proc = run_python(WITHOUT_ROSBAGS + code)
    return proc.returncode, proc.stdout.decode().strip(), proc.stderr.decode()


@pytest.mark.parametrize("package", ["geometry_msgs", "nav_msgs", "std_srvs"])
def test_a_definition_without_rosbags_is_one_line_naming_the_extra(package):
    kind = "srv" if package == "std_srvs" else "msg"
    code, out, err = _run("from twinfleet.interfaces import InterfaceError, load_interface\n"
                          "try:\n"
                          f"    module = load_interface({package!r}, {kind!r})\n"
                          "    getattr(module, module.__all__[0])\n"
                          "except InterfaceError as exc:\n"
                          "    print(exc)\n")
    assert code == 0, err
    assert out == ("ROS 2 message definitions need rosbags, which is not installed: "
                   "pip install 'twinfleet[rclpy]'")


def test_native_types_with_any_name_load_without_rosbags():
    code, out, err = _run("from twinfleet.interfaces.guard import install\n"
                          "from twinfleet import message\n"
                          "install()\n"
                          "@message('geometry_msgs/Twist')\n"
                          "class Flat:\n"
                          "    x: float = 0.0\n"
                          "print('loaded')\n")
    assert code == 0, err
    assert out == "loaded"
