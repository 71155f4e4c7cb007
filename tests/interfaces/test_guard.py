"""A user's type that borrows a standard ROS 2 name with other fields is refused at load."""

from __future__ import annotations

import dataclasses
import textwrap

import pytest
import yaml

from tests.interfaces.fresh import run_python
from twinfleet.cli import main
from twinfleet.interfaces.guard import check_type, install
from twinfleet.runtime.contract.messages import String, message, registered_types

pytestmark = pytest.mark.timeout(60)

FLAT_TWIST = textwrap.dedent("""
    from twinfleet import Node, message, on_start

    @message("geometry_msgs/Twist")
    class Twist:
        x: float = 0.0
        y: float = 0.0
        theta: float = 0.0

    class Driver(Node):
        @on_start
        def begin(self, ctx):
            ctx.publish("/cmd_vel", Twist(x=1.0))
""")


def test_a_flat_twist_is_refused_with_one_line():
    install()
    with pytest.raises(TypeError) as caught:
        @message("geometry_msgs/Twist")
        class Twist:
            x: float = 0.0
            theta: float = 0.0
    line = str(caught.value)
    assert "\n" not in line
    assert line.startswith("geometry_msgs/Twist (tests.interfaces.test_guard.")
    assert ("its fields are (x, theta), unlike the standard ROS 2 type geometry_msgs/msg/Twist "
            "(linear: geometry_msgs/Vector3, angular: geometry_msgs/Vector3)") in line
    assert registered_types().get("geometry_msgs/Twist", object).__module__ != __name__


def test_same_names_other_kinds_and_unknown_types_of_a_standard_package_are_refused():
    install()
    with pytest.raises(TypeError, match="its field data holds an integer, not a text"):
        @message("std_msgs/msg/String")
        class Text:
            data: int = 0
    with pytest.raises(TypeError, match="geometry_msgs is a standard ROS 2 package without a "
                                        "type Pose2DPlus"):
        @message("geometry_msgs/Pose2DPlus")
        class Pose:
            x: float = 0.0


def test_a_faithful_copy_and_types_of_other_packages_pass():
    install()

    @message("my_msgs/Twist")
    class Mine:
        x: float = 0.0

    @dataclasses.dataclass(frozen=True)
    class Vector3:  # checked only, not registered: no type leaks into other tests
        x: float = 0.0
        y: float = 0.0
        z: float = 0.0

    check_type("geometry_msgs/Vector3", Vector3)
    check_type("geometry_msgs/msg/Vector3", Vector3)
    assert registered_types()["my_msgs/Twist"] is Mine


def test_the_contract_s_own_standard_types_have_ros_2_s_fields():
    """The guard skips twinfleet's own types; this is what makes that safe."""
    for name, cls in registered_types().items():
        if name.startswith("std_msgs/") and cls.__module__ == String.__module__:
            check_type(name, type("Copy", (cls,), {"__module__": "user"}))


def test_loading_a_scenario_with_a_borrowed_name_is_one_line_exit_2(tmp_path, capsys,
                                                                   monkeypatch):
    (tmp_path / "flat_twist_nodes.py").write_text(FLAT_TWIST)
    monkeypatch.syspath_prepend(str(tmp_path))
    scenario = tmp_path / "s.yaml"
    scenario.write_text(yaml.safe_dump({"name": "flat", "nodes": [
        {"name": "driver", "class": "flat_twist_nodes:Driver"}]}))
    code = main(["check", str(scenario), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2, err
    (line,) = [x for x in err.splitlines() if not x.startswith("warning:")]
    assert "flat_twist_nodes" in line and "geometry_msgs/Twist" in line
    assert "unlike the standard ROS 2 type geometry_msgs/msg/Twist" in line


def test_types_of_other_packages_cost_no_rosbags_store():
    """The guard asks about every type a command registers; the store's module imports every
    older distribution's store (about 0.2 s), so its names are read from its source."""
    code = ("import sys\n"
            "from twinfleet.interfaces.guard import install\n"
            "from twinfleet import message\n"
            "install()\n"
            "@message('my_robot_msgs/Status')\n"
            "class Status:\n"
            "    ok: bool = True\n"
            "print(any(m.startswith('rosbags.typesys.stores') for m in sys.modules))\n")
    proc = run_python(code)
    assert proc.returncode == 0, proc.stderr.decode()
    assert proc.stdout.decode().strip() == "False"
    from rosbags.typesys import Stores, get_typestore

    from twinfleet.interfaces.definitions import _store_names

    assert _store_names() == frozenset(get_typestore(Stores.ROS2_JAZZY).fielddefs)
