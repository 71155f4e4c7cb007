"""RIHS01 hashes against rosidl's: the generated ``share/<pkg>/msg/<Type>.json`` files.

Jazzy: the ``ros-jazzy-*-msgs`` packages of the test extra install rosidl's
generated files under ``<prefix>/share``; every message type there that the
type store knows must hash as rosidl hashed it. Kilted (whose packages cannot
be installed beside Jazzy's): the hashes of ``ros-kilted-std-msgs`` 5.5.1,
``ros-kilted-nav-msgs`` 5.5.1 and its ``ros-geometry-msgs`` 5.5.1, copied from
their ``*.json`` into tests/ros2/data/kilted_hashes.json.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
from rosbags.typesys import Stores, get_typestore

from twinfleet.interfaces.typehash import rihs01, store_lookup
from twinfleet.ros2.cdr import RosTypes

pytestmark = pytest.mark.offline  # starts no fleet, opens no Zenoh session

SHARE = Path(sys.prefix) / "share"
MAPPED = ("nav_msgs/msg/OccupancyGrid", "geometry_msgs/msg/PoseStamped", "nav_msgs/msg/Path",
          "sensor_msgs/msg/LaserScan", "std_msgs/msg/Char", "std_msgs/msg/String")


def _rosidl_hash(ros_type: str) -> str:
    pkg, _, name = ros_type.split("/")
    doc = json.loads((SHARE / pkg / "msg" / f"{name}.json").read_text())
    return str(doc["type_hashes"][0]["hash_string"])


@pytest.mark.parametrize("ros_type", MAPPED)
def test_every_mapped_type_hashes_as_rosidl(ros_type):
    assert RosTypes().type_hash(ros_type) == _rosidl_hash(ros_type)


def test_every_installed_jazzy_message_hashes_as_rosidl():
    store = get_typestore(Stores.ROS2_JAZZY)
    checked = []
    for path in sorted(SHARE.glob("*/msg/*.json")):
        name = f"{path.parts[-3]}/msg/{path.stem}"
        if name in store.fielddefs:
            assert rihs01(name, store_lookup(store)) == _rosidl_hash(name), name
            checked.append(name)
    assert len(checked) > 100  # std, geometry, nav, sensor, builtin_interfaces, ...


def test_rosbags_own_hash_is_wrong_for_char_fields_and_ours_is_right():
    store = get_typestore(Stores.ROS2_JAZZY)
    rosidl = _rosidl_hash("std_msgs/msg/Char")
    assert store.hash_rihs01("std_msgs/msg/Char") != rosidl  # rosbags: char is type id 13
    assert rihs01("std_msgs/msg/Char", store_lookup(store)) == rosidl
    assert store.hash_rihs01("std_msgs/msg/String") == rihs01("std_msgs/msg/String",
                                                             store_lookup(store))


def test_a_char_field_inside_another_type_hashes_as_rosidl():
    """test_msgs/msg/BasicTypes (bool, byte, char, every number) is not in rosbags' store:
    registered from its .msg, it must hash as rosidl's BasicTypes.json says."""
    from rosbags.typesys import get_types_from_msg

    store = get_typestore(Stores.EMPTY)
    text = (SHARE / "test_msgs" / "msg" / "BasicTypes.msg").read_text()
    store.register(get_types_from_msg(text, "test_msgs/msg/BasicTypes"))
    expected = _rosidl_hash("test_msgs/msg/BasicTypes")
    assert rihs01("test_msgs/msg/BasicTypes", store_lookup(store)) == expected


def test_kilted_hashes_equal_rosidls():
    golden = json.loads((Path(__file__).parent / "data" / "kilted_hashes.json").read_text())
    store = get_typestore(Stores.ROS2_KILTED)
    assert "std_msgs/msg/Char" in golden
    for name, expected in golden.items():
        assert rihs01(name, store_lookup(store)) == expected, name
