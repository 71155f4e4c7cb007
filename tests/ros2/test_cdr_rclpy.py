"""CDR against rclpy's own: what the bridge encodes decodes in `rclpy.serialization` to the
same values, and rclpy's bytes decode in the bridge (compared by value: padding differs).

The messages are what the robot mapping makes of real fleet messages, so every mapped
type is covered as the bridge sends it."""

from __future__ import annotations

import math

import pytest
from rclpy.serialization import deserialize_message, serialize_message

from twinfleet.nodes.msgs import ObstacleScan, OccupancyGrid, Path, RobotPose
from twinfleet.nodes.ros2_mapping import RobotRos2Mapping
from twinfleet.ros2.cdr import MessageError, RosTypes

pytestmark = pytest.mark.offline  # starts no fleet, opens no Zenoh session

GRID = OccupancyGrid(4, 3, 0.5, (1.0, -2.0, 0.0), bytes([0, 100, 255, 0] * 3))


def get_message(ros_type):
    """The rclpy class of `pkg/msg/Name`."""
    import importlib

    pkg, sub, name = ros_type.split("/")
    return getattr(importlib.import_module(f"{pkg}.{sub}"), name)


def message_to_ordereddict(msg):
    """An rclpy message as nested dicts (lists for sequences)."""
    if hasattr(msg, "get_fields_and_field_types"):
        return {k: message_to_ordereddict(getattr(msg, k)) for k in msg.get_fields_and_field_types()}
    if isinstance(msg, list | tuple) or hasattr(msg, "tolist"):
        return [message_to_ordereddict(v) for v in msg]
    return msg


def set_message_fields(msg, fields):
    """Set an rclpy message's fields from nested dicts."""
    for key, value in fields.items():
        current = getattr(msg, key)
        if hasattr(current, "get_fields_and_field_types"):
            set_message_fields(current, value)
        elif isinstance(value, list) and value and isinstance(value[0], dict):
            cls = type(current[0]) if current else _element_class(msg, key)
            items = []
            for item in value:
                made = cls()
                set_message_fields(made, item)
                items.append(made)
            setattr(msg, key, items)
        else:
            setattr(msg, key, value)


def _element_class(msg, key):
    kind = msg.get_fields_and_field_types()[key]  # e.g. sequence<geometry_msgs/PoseStamped>
    pkg, name = kind[kind.index("<") + 1:kind.rindex(">")].split("/")
    return get_message(f"{pkg}/msg/{name}")


def _fields(msg):
    import dataclasses

    return {f.name: getattr(msg, f.name) for f in dataclasses.fields(msg)}


def mapped_messages():
    table = RobotRos2Mapping()
    out = []
    out += table.outbound("/map", "twinfleet_msgs/OccupancyGrid", _fields(GRID), 1500)
    out += table.outbound("/poses", "twinfleet_msgs/RobotPose",
                          _fields(RobotPose("r1", (1, 2), 3, 1)), 1600)
    out += table.outbound("/r1/scan", "twinfleet_msgs/ObstacleScan",
                          _fields(ObstacleScan("r1", ((1, 3), (0, 0)))), 1700)
    out += table.outbound("/r1/path", "twinfleet_msgs/Path",
                          _fields(Path(((1, 2), (2, 2), (2, 3)))), 1800)
    return out


def _same(ours, theirs, where=""):
    if isinstance(ours, dict):
        assert set(ours) == set(theirs), where
        for k in ours:
            _same(ours[k], theirs[k], f"{where}.{k}")
    elif isinstance(ours, list | tuple | bytes):
        theirs = list(theirs)
        assert len(ours) == len(theirs), where
        for i, (a, b) in enumerate(zip(ours, theirs, strict=True)):
            _same(a, b, f"{where}[{i}]")
    elif isinstance(ours, float):
        assert ours == pytest.approx(float(theirs), rel=1e-6) or (
            math.isinf(ours) and math.isinf(theirs)), where
    else:
        assert ours == theirs, where


def _plain(value):
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if hasattr(value, "tolist"):
        return value.tolist()
    return value


def test_every_mapped_type_is_covered():
    assert {t for _, t, _ in mapped_messages()} == {
        "nav_msgs/msg/OccupancyGrid", "geometry_msgs/msg/PoseStamped", "tf2_msgs/msg/TFMessage",
        "sensor_msgs/msg/LaserScan", "nav_msgs/msg/Path"}


@pytest.mark.parametrize(("topic", "ros_type", "fields"),
                         [m for m in mapped_messages() if not m[1].startswith("tf2_msgs")]
                         + [("/tf", "geometry_msgs/msg/TransformStamped", m[2]["transforms"][0])
                            for m in mapped_messages() if m[1].startswith("tf2_msgs")])
def test_ours_decode_in_rclpy_and_rclpys_in_ours(topic, ros_type, fields):
    types = RosTypes()
    ours = types.encode(ros_type, fields)
    assert ours[:4] == b"\x00\x01\x00\x00"
    cls = get_message(ros_type)
    theirs = deserialize_message(ours, cls)
    decoded = types.decode(ros_type, ours)
    _same(decoded, _plain(message_to_ordereddict(theirs)), topic)
    # and back: rclpy's bytes of the same message decode in ours to the same values
    again = cls()
    set_message_fields(again, _rclpy_fields(decoded))
    _same(decoded, types.decode(ros_type, serialize_message(again)), topic)


def _rclpy_fields(value):
    """rosidl_runtime_py takes int8 sequences as ints (-1), bytes otherwise as lists."""
    if isinstance(value, dict):
        return {k: _rclpy_fields(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_rclpy_fields(v) for v in value]
    return value


def test_occupancy_keeps_free_occupied_and_unknown():
    grid = next(f for _, t, f in mapped_messages() if t == "nav_msgs/msg/OccupancyGrid")
    cls = get_message("nav_msgs/msg/OccupancyGrid")
    msg = deserialize_message(RosTypes().encode("nav_msgs/msg/OccupancyGrid", grid), cls)
    assert list(msg.data)[:4] == [0, 100, -1, 0]
    assert (msg.info.width, msg.info.height, msg.info.resolution) == (4, 3, 0.5)
    assert (msg.info.origin.position.x, msg.info.origin.position.y) == (1.0, -2.0)


def test_char_and_every_primitive_round_trip_with_rclpy():
    """test_msgs/msg/BasicTypes (bool, byte, char, every number), registered from its .msg."""
    import sys
    from pathlib import Path

    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.EMPTY)
    text = (Path(sys.prefix) / "share/test_msgs/msg/BasicTypes.msg").read_text()
    store.register(get_types_from_msg(text, "test_msgs/msg/BasicTypes"))
    types = RosTypes(store)
    fields = {"bool_value": True, "byte_value": 255, "char_value": 65, "float32_value": 1.5,
              "float64_value": -2.25, "int8_value": -128, "uint8_value": 255,
              "int16_value": -32768, "uint16_value": 65535, "int32_value": -2**31,
              "uint32_value": 2**32 - 1, "int64_value": -2**63, "uint64_value": 2**64 - 1}
    cls = get_message("test_msgs/msg/BasicTypes")
    theirs = deserialize_message(types.encode("test_msgs/msg/BasicTypes", fields), cls)
    plain = _plain(message_to_ordereddict(theirs))
    plain["byte_value"] = plain["byte_value"][0] if isinstance(plain["byte_value"], bytes) else plain["byte_value"]
    _same(fields, plain)
    _same(fields, types.decode("test_msgs/msg/BasicTypes", serialize_message(theirs)))


def test_malformed_input_is_refused_with_where():
    types = RosTypes()
    with pytest.raises(MessageError, match="not a geometry_msgs/msg/PoseStamped"):
        types.decode("geometry_msgs/msg/PoseStamped", b"\x00\x01\x00\x00\x01")
    nan_pose = types.encode("geometry_msgs/msg/PoseStamped",
                            {"pose": {"position": {"x": float("nan")}}})
    assert math.isnan(types.decode("geometry_msgs/msg/PoseStamped", nan_pose)["pose"]["position"]["x"])
    with pytest.raises(MessageError, match=r"pose\.position\.x is not a finite number"):
        types.decode("geometry_msgs/msg/PoseStamped", nan_pose, strict=True)
    with pytest.raises(MessageError, match="has no field 'bogus'"):
        types.encode("std_msgs/msg/String", {"bogus": 1})
    with pytest.raises(MessageError, match="out of range for int8"):
        types.encode("std_msgs/msg/Int8", {"data": 300})
