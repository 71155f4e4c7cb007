"""`twinfleet interface export --ros2 DIR`: the package's .msg files run through rosidl's own
generators (ros-rosidl-adapter: .msg → .idl; ros-rosidl-generator-type-description: the
type description JSON and its RIHS01 hash, as colcon's build of the package would) give the
hashes the bridge announces for the types it carries by their fields; the bridge's CDR of a
fleet message decodes to its fields."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from twinfleet.cli import main
from twinfleet.nodes.msgs import FleetStatus, RobotStatus
from twinfleet.ros2.live import fleet_interfaces
from twinfleet.runtime.contract.messages import to_plain

pytestmark = pytest.mark.offline  # starts no fleet, opens no Zenoh session

rosidl_adapter = pytest.importorskip("rosidl_adapter.msg")
type_description = pytest.importorskip("rosidl_generator_type_description")
PKG = "twinfleet_msgs"


def _rosidl_hashes(package: Path, out: Path) -> dict[str, str]:
    """rosidl's RIHS01 of every .msg in `package` (its generators, as a build runs them)."""
    idl_dir = out / "idl"
    tuples = []
    for msg in sorted((package / "msg").glob("*.msg")):
        rosidl_adapter.convert_msg_to_idl(package, PKG, Path("msg") / msg.name, idl_dir / "msg")
        tuples.append(f"{idl_dir}:msg/{msg.stem}.idl")
    args = out / "args.json"
    args.write_text(json.dumps({"package_name": PKG, "output_dir": str(out / "json"),
                                "idl_tuples": tuples, "include_paths": []}))
    type_description.generate_type_hash(str(args))
    hashes = {}
    for made in (out / "json" / "msg").glob("*.json"):
        for entry in json.loads(made.read_text())["type_hashes"]:
            hashes[entry["type_name"]] = entry["hash_string"]
    return hashes


def test_the_exported_package_has_the_hashes_the_bridge_announces(tmp_path):
    assert main(["interface", "export", "--ros2", str(tmp_path)]) == 0
    package = tmp_path / PKG
    xml = ET.parse(package / "package.xml").getroot()
    assert xml.get("format") == "3" and xml.findtext("name") == PKG
    assert xml.findtext("member_of_group") == "rosidl_interface_packages"
    cmake = (package / "CMakeLists.txt").read_text()
    msgs = sorted(p.name for p in (package / "msg").glob("*.msg"))
    assert all(f'"msg/{m}"' in cmake for m in msgs) and "RobotStatus.msg" in msgs
    rosidl = _rosidl_hashes(package, tmp_path / "build")
    ours = fleet_interfaces()
    assert len(rosidl) == len(msgs) >= 10
    for type_name, expected in rosidl.items():
        assert ours.types.type_hash(type_name) == expected, type_name


def test_a_fleet_message_carried_by_its_fields_decodes_to_them():
    ours = fleet_interfaces()
    status = RobotStatus("r1", "moving", (3, 4), (5, 6), 1, 0, 1200)
    fields = ours.fields("twinfleet_msgs/RobotStatus", to_plain(status))
    back = ours.types.decode("twinfleet_msgs/msg/RobotStatus",
                             ours.types.encode("twinfleet_msgs/msg/RobotStatus", fields))
    assert back["cell"] == [3, 4] and back["mode"] == "moving" and back["time_ms"] == 1200
    fleet = FleetStatus(("r1", "r2"), ((1, 2), (3, 4)), 0, 50)
    fields = ours.fields("twinfleet_msgs/FleetStatus", to_plain(fleet))
    back = ours.types.decode("twinfleet_msgs/msg/FleetStatus",
                             ours.types.encode("twinfleet_msgs/msg/FleetStatus", fields))
    assert back["cells"] == [{"values": [1, 2]}, {"values": [3, 4]}]
    assert back["robots"] == ["r1", "r2"]
