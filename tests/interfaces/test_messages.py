"""Generated message classes: rosidl's constructor, freeze/thaw, the contract's codec, errors."""

from __future__ import annotations

import copy

import pytest

from twinfleet.interfaces import (
    FieldValueError,
    InterfaceError,
    freeze,
    from_fields,
    load_interface,
    message_type,
    thaw,
)
from twinfleet.runtime.contract.messages import String, decode, encode, registered_types

pytestmark = pytest.mark.timeout(60)

geometry = load_interface("geometry_msgs", "msg")
sensor = load_interface("sensor_msgs", "msg")
std_msgs = load_interface("std_msgs", "msg")


def test_constructor_is_keyword_only_with_defaults_and_nested_messages():
    twist = geometry.Twist(linear=geometry.Vector3(x=1.0))
    assert twist.linear.x == 1.0 and twist.angular == geometry.Vector3()
    with pytest.raises(TypeError):
        geometry.Twist(geometry.Vector3())  # positional, as rosidl refuses it
    with pytest.raises(TypeError, match="has no field 'linear_x'"):
        geometry.Twist(linear_x=1.0)
    assert len(sensor.Imu().orientation_covariance) == 9
    assert sensor.Imu().orientation_covariance is not sensor.Imu().orientation_covariance
    assert not hasattr(geometry.Twist(), "__dict__")  # __slots__, as rosidl's


def test_equality_and_repr_read_like_rosidl_s():
    assert geometry.Vector3(x=1.0) == geometry.Vector3(x=1.0)
    assert geometry.Vector3(x=1.0) != geometry.Vector3(x=2.0)
    assert geometry.Point(x=1.0) != geometry.Vector3(x=1.0)  # same fields, other type
    assert repr(geometry.Vector3()) == "geometry_msgs.msg.Vector3(x=0.0, y=0.0, z=0.0)"


def test_freeze_makes_a_contract_message_that_the_codec_carries():
    twist = geometry.Twist()
    twist.linear.x = 0.5
    frozen = freeze(twist)
    assert type(frozen).__message_type__ == "geometry_msgs/Twist"
    assert registered_types()["geometry_msgs/Twist"] is type(frozen)
    assert decode(encode(frozen)).msg == frozen
    with pytest.raises(AttributeError):
        frozen.linear.x = 2.0  # frozen all the way down


def test_thaw_gives_a_new_mutable_message_each_time():
    frozen = freeze(sensor.Imu(orientation_covariance=[1.0] * 9))
    first, second = thaw(frozen), thaw(frozen)
    assert first == second and first is not second
    first.orientation_covariance[0] = 5.0
    assert second.orientation_covariance[0] == 1.0
    assert freeze(first) != frozen and freeze(second) == frozen


def test_publishing_copies_what_the_node_keeps_changing():
    twist = geometry.Twist()
    frozen = freeze(twist)
    twist.linear.x = 3.0
    assert frozen.linear.x == 0.0


def test_the_contract_s_own_standard_types_are_shared_with_native_nodes():
    assert type(freeze(std_msgs.String(data="hi"))) is String
    assert thaw(String(data="hi")) == std_msgs.String(data="hi")


@pytest.mark.parametrize(("build", "line"), [
    (lambda: geometry.Twist(linear=geometry.Vector3(x="fast")),
     "geometry_msgs/msg/Twist.linear.x: expected a number (float64), got 'fast'"),
    (lambda: sensor.Imu(orientation_covariance=[0.0] * 8),
     "sensor_msgs/msg/Imu.orientation_covariance: expected 9 values, got 8"),
    (lambda: std_msgs.UInt8(data=256),
     "std_msgs/msg/UInt8.data: 256 is out of range for uint8 (0..255)"),
    (lambda: geometry.Twist(linear=geometry.Point()),
     "geometry_msgs/msg/Twist.linear: expected a geometry_msgs/msg/Vector3, got Point"),
])
def test_a_wrong_value_is_one_line_at_freeze(build, line):
    with pytest.raises(FieldValueError) as caught:
        freeze(build())
    assert str(caught.value) == line


def test_bounded_sequences_are_checked():
    params = load_interface("rcl_interfaces", "msg")
    descriptor = params.ParameterDescriptor()
    descriptor.integer_range = [params.IntegerRange(), params.IntegerRange()]
    with pytest.raises(FieldValueError, match="integer_range: 2 values, more than the bound 1"):
        freeze(descriptor)


def test_services_have_request_and_response_classes():
    srv = load_interface("std_srvs", "srv")
    assert srv.SetBool.__ros_type__ == "std_srvs/srv/SetBool"
    request = srv.SetBool.Request(data=True)
    assert request.data is True and srv.SetBool.Response().message == ""
    assert type(freeze(request)).__message_type__ == "std_srvs/SetBool_Request"


def test_from_fields_reads_ros_users_yaml_values():
    twist = from_fields("geometry_msgs/msg/Twist", {"linear": {"x": 1.0}})
    assert twist == geometry.Twist(linear=geometry.Vector3(x=1.0))
    with pytest.raises(FieldValueError, match=r"Twist\.linear: unknown field 'w' \(fields of "
                                              r"geometry_msgs/msg/Vector3: x, y, z\)"):
        from_fields("geometry_msgs/msg/Twist", {"linear": {"w": 1.0}})
    path = from_fields("nav_msgs/msg/Path", {"poses": [{"pose": {"position": {"x": 2.0}}}]})
    assert path.poses[0].pose.position.x == 2.0 and path.poses[0].pose.orientation.w == 1.0
    with pytest.raises(FieldValueError, match=r"Path\.poses: expected a list, got \{'pose': 1\}"):
        from_fields("nav_msgs/msg/Path", {"poses": {"pose": 1}})


def test_unknown_interfaces_are_one_line_naming_what_to_install():
    with pytest.raises(InterfaceError, match=r"unknown ROS 2 interface package nope_msgs\.msg: "
                                             r"no definitions installed \(install "
                                             r"ros-jazzy-nope-msgs"):
        load_interface("nope_msgs", "msg")
    with pytest.raises(AttributeError, match="geometry_msgs has no msg 'Twister'"):
        _ = geometry.Twister
    with pytest.raises(InterfaceError, match="package geometry_msgs has no such msg"):
        message_type("geometry_msgs/msg/Twister")


def test_deepcopy_keeps_the_class():
    twist = geometry.Twist()
    twist.linear.x = 1.0
    assert copy.deepcopy(twist) == twist


def test_known_packages_are_the_store_s_and_the_installed_ones():
    from twinfleet.interfaces.definitions import known_packages, standard_packages

    known = known_packages()
    assert {"std_msgs", "geometry_msgs", "tf2_msgs", "std_srvs", "test_msgs"} <= set(known)
    assert "std_srvs" not in standard_packages() and "tf2_msgs" in standard_packages()


def test_freeze_converts_what_rclpy_accepts_and_refuses_the_rest():
    import numpy as np

    assert freeze(geometry.Vector3(x=1, y=np.float64(2.5))) == freeze(
        geometry.Vector3(x=1.0, y=2.5))
    assert type(freeze(geometry.Vector3(x=1)).x) is float
    image = sensor.Image(data=b"\x00\x01\xff")  # uint8[] takes bytes, as rosidl's array('B')
    assert freeze(image).data == (0, 1, 255)
    assert freeze(sensor.Imu(orientation_covariance=tuple([2.0] * 9))).orientation_covariance \
        == (2.0,) * 9
    with pytest.raises(FieldValueError, match=r"Bool\.data: expected True or False, got 1"):
        freeze(std_msgs.Bool(data=1))
    with pytest.raises(FieldValueError, match=r"Image\.data\[1\]: 256 is out of range for uint8"):
        freeze(sensor.Image(data=[0, 256]))
    strings = load_interface("test_msgs", "msg").Strings(bounded_string_value="x" * 23)
    with pytest.raises(FieldValueError, match="bounded_string_value: 23 characters, more than "
                                              "the bound 22"):
        freeze(strings)


def test_empty_messages_construct_and_round_trip():
    empty = std_msgs.Empty()
    assert thaw(freeze(empty)) == empty
    with pytest.raises(TypeError, match="has no field 'x'"):
        std_msgs.Empty(x=1)


def test_a_ros_installation_s_own_packages_load_from_ament_prefix_path(tmp_path, monkeypatch):
    share = tmp_path / "install" / "share" / "my_robot_interfaces"
    (share / "msg").mkdir(parents=True)
    (share / "srv").mkdir()
    (share / "msg" / "Battery.msg").write_text(
        "uint8 FULL=100\nfloat32 volts 12.5  # nominal\nstd_msgs/Header header\nPose2[2] marks\n")
    (share / "msg" / "Pose2.msg").write_text("float64 x\nfloat64 y\n")
    (share / "srv" / "Dock.srv").write_text("string station\n---\nbool ok\n")
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(tmp_path / "install"))
    battery = load_interface("my_robot_interfaces", "msg").Battery()
    assert battery.volts == 12.5 and battery.FULL == 100 and len(battery.marks) == 2
    assert battery.get_fields_and_field_types() == {
        "volts": "float", "header": "std_msgs/Header", "marks": "my_robot_interfaces/Pose2[2]"}
    dock = load_interface("my_robot_interfaces", "srv").Dock
    assert dock.Request(station="a").station == "a" and dock.Response().ok is False
    assert thaw(freeze(battery)) == battery


def test_messages_pickle_and_snapshot_into_a_fresh_process():
    """Ray workers and checkpoints pickle what nodes hold and what travels, and the checker's
    state snapshot names a dataclass by module and qualified name: a generated class is
    found again in a process that has not generated it yet."""
    import pickle

    from tests.interfaces.fresh import run_python
    from twinfleet.runtime.contract.snapshot import snapshot

    twist = geometry.Twist(linear=geometry.Vector3(x=2.0))
    blob = pickle.dumps([twist, freeze(twist), freeze(std_msgs.String(data="s")),
                         snapshot({"last": freeze(twist), "imu": freeze(sensor.Imu())})])
    code = ("import pickle, sys\n"
            "from twinfleet.runtime.contract.snapshot import restore\n"
            "mutable, frozen, text, state = pickle.loads(sys.stdin.buffer.read())\n"
            "state = restore(state)\n"
            "print(mutable.linear.x, frozen.linear.x, type(frozen).__message_type__, text.data,\n"
            "      state['last'] == frozen, state['imu'].orientation.w, repr(frozen)[:24])\n")
    proc = run_python(code, blob)
    assert proc.returncode == 0, proc.stderr.decode()
    assert proc.stdout.decode().split() == ["2.0", "2.0", "geometry_msgs/Twist", "s", "True",
                                            "1.0", "geometry_msgs.msg.Twist("]


def test_copies_do_not_check_values():
    twist = geometry.Twist()
    twist.linear.x = "not yet a number"  # rclpy code may hold anything until it publishes
    assert copy.deepcopy(twist).linear.x == "not yet a number"
    shallow = copy.copy(twist)
    assert shallow.linear is twist.linear and shallow == twist


def test_numpy_scalars_freeze_as_python_numbers():
    import numpy as np

    frozen = freeze(std_msgs.Int32(data=np.int64(5)))
    assert frozen.data == 5 and type(frozen.data) is int
    assert type(freeze(std_msgs.Float32(data=np.float32(1.5))).data) is float
    with pytest.raises(FieldValueError, match=r"Int32\.data: expected an integer \(int32\), "
                                              "got True"):
        freeze(std_msgs.Int32(data=True))
