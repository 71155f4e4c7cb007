"""Generated classes against rosidl's: the real classes of the ``ros-jazzy-*`` wheels.

For every message type of the standard packages the test extra installs (and the
request and response of every service of std_srvs and rcl_interfaces), our class
and rosidl's have the same `get_fields_and_field_types()` and equal
default-constructed values, and our RIHS01 is the hash of rosidl's
``share/<pkg>/<kind>/<Type>.json``.
"""

from __future__ import annotations

import array
import importlib
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from twinfleet.interfaces import load_interface
from twinfleet.interfaces.definitions import package_types, share_dirs

pytestmark = pytest.mark.timeout(120)

MESSAGE_PACKAGES = ("builtin_interfaces", "std_msgs", "geometry_msgs", "sensor_msgs", "nav_msgs",
                    "rcl_interfaces")
SERVICE_PACKAGES = ("std_srvs", "rcl_interfaces")


def _json(package: str, kind: str, name: str) -> Path:
    for share in share_dirs():
        path = share / package / kind / f"{name}.json"
        if path.is_file():
            return path
    raise AssertionError(f"rosidl's {package}/{kind}/{name}.json is not installed")


def _plain(value: Any) -> Any:
    """A message's values as plain data: rosidl's numpy and array.array become lists."""
    if hasattr(type(value), "get_fields_and_field_types"):
        return {name: _plain(getattr(value, name))
                for name in type(value).get_fields_and_field_types()}
    if isinstance(value, np.ndarray | array.array | list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def _types(kind: str, packages: tuple[str, ...]) -> list[tuple[str, str]]:
    return [(pkg, name) for pkg in packages for name in package_types(pkg, kind)]


@pytest.mark.parametrize(("package", "name"), _types("msg", MESSAGE_PACKAGES))
def test_message_class_matches_rosidl(package, name):
    ours = getattr(load_interface(package, "msg"), name)
    theirs = getattr(importlib.import_module(f"{package}.msg"), name)
    assert ours.get_fields_and_field_types() == theirs.get_fields_and_field_types()
    assert _plain(ours()) == _plain(theirs())
    expected = json.loads(_json(package, "msg", name).read_text())["type_hashes"][0]
    assert ours.__ros_type__ == expected["type_name"] == f"{package}/msg/{name}"
    assert ours.__type_hash__ == expected["hash_string"]


@pytest.mark.parametrize(("package", "name"), _types("srv", SERVICE_PACKAGES))
def test_service_class_matches_rosidl(package, name):
    ours = getattr(load_interface(package, "srv"), name)
    theirs = getattr(importlib.import_module(f"{package}.srv"), name)
    for part in ("Request", "Response"):
        mine, real = getattr(ours, part), getattr(theirs, part)
        assert mine.get_fields_and_field_types() == real.get_fields_and_field_types()
        assert _plain(mine()) == _plain(real())
    hashes = {h["type_name"]: h["hash_string"]
              for h in json.loads(_json(package, "srv", name).read_text())["type_hashes"]}
    assert ours.__ros_type__ == f"{package}/srv/{name}"
    assert ours.__type_hash__ == hashes[ours.__ros_type__]
    assert ours.Request.__type_hash__ == hashes[f"{ours.__ros_type__}_Request"]
    assert ours.Response.__type_hash__ == hashes[f"{ours.__ros_type__}_Response"]


def test_the_packages_hold_what_rosidl_generates():
    for package in MESSAGE_PACKAGES:
        real = importlib.import_module(f"{package}.msg")
        generated = {n for n in dir(real) if n[:1].isupper() and not n.startswith("Metaclass")}
        assert set(package_types(package, "msg")) == generated, package
    assert package_types("std_srvs", "srv") == ("Empty", "SetBool", "Trigger")


def test_constants_and_non_zero_defaults_are_rosidl_s():
    sensor = load_interface("sensor_msgs", "msg")
    assert sensor.NavSatStatus.STATUS_FIX == 0 and sensor.NavSatStatus.STATUS_NO_FIX == -1
    assert sensor.NavSatStatus().status == -2  # `int8 status -2` in the .msg
    assert load_interface("geometry_msgs", "msg").Quaternion().w == 1.0
