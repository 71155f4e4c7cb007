"""`twinfleet export run.mcap --ros2 -o BAG/`: a rosbag2 folder that two readers that are
not ours (rosbags' rosbag2 reader, mcap-ros2-support's decoder) read with the recording's
types, counts, timestamps and values."""

from __future__ import annotations

import dataclasses
import math
import re
import sys
import time

import msgpack
import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from twinfleet.cli import main
from twinfleet.nodes.msgs import ObstacleScan, OccupancyGrid, Path, RobotPose
from twinfleet.nodes.ros2_mapping import RobotRos2Mapping
from twinfleet.ros2.cdr import RosTypes
from twinfleet.ros2.interfaces import fleet_interfaces
from twinfleet.runtime.contract.messages import String, encode
from twinfleet.runtime.tools.record.recorder import McapRecorder

pytestmark = pytest.mark.offline  # starts no fleet, opens no Zenoh session

GRID = OccupancyGrid(4, 3, 0.5, (1.0, -2.0, 0.0), bytes([0, 100, 255, 0] * 3))
SCENE = "twinfleet.nodes.scene:RobotScene"


@pytest.fixture
def recording(tmp_path):
    """A small recording as `twinfleet record` writes it: the map, then poses, scans, plans."""
    path = tmp_path / "run.mcap"
    rec = McapRecorder(path.open("wb"), latched=("/map",))
    rec.metadata({"fleet": "f", "scene": SCENE})
    sent = [("twinfleet/f/map", GRID)]
    for i in range(5):
        sent.append(("twinfleet/f/poses", RobotPose("r1", (1, i % 4), i % 8, 1)))
        sent.append(("twinfleet/f/r1/scan", ObstacleScan("r1", ((2, i % 4), (0, 0)))))
    sent.append(("twinfleet/f/r1/path", Path(((1, 1), (1, 2)))))
    for seq, (key, msg) in enumerate(sent, 1):
        rec.write(key, encode(msg, seq=seq, stamp_ms=100 * seq))
    rec.close()
    return path, sent


def _expected(sent):
    """What the mapping makes of the recording, in order: (topic, type, fields, fleet ns);
    a message the mapping puts only on other topics is on its own topic too, by fields."""
    table = RobotRos2Mapping()
    out = []
    for seq, (key, msg) in enumerate(sent, 1):
        fields = {f.name: getattr(msg, f.name) for f in dataclasses.fields(msg)}
        fields = {k: list(v) if isinstance(v, tuple) else v for k, v in fields.items()}
        topic = key.removeprefix("twinfleet/f")
        made = table.outbound(topic, msg.__message_type__, fields, 100 * seq)
        if all(t != topic for t, _, _ in made):
            made.append((topic, msg.__message_type__.replace("/", "/msg/"), BY_FIELDS[topic](msg)))
        out += [(*m, 100 * seq * 1_000_000) for m in made]
    return out


BY_FIELDS = {"/poses": lambda m: {"robot": m.robot, "cell": list(m.cell),
                                  "direction": m.direction, "velocity": m.velocity,
                                  "done": m.done},
             "/r1/path": lambda m: {"cells": [{"values": list(c)} for c in m.cells]}}


def register_msgdef(store, msgdef: str, name: str) -> None:
    """Register a type from the full message definition a bag carries (its own text, then
    each type it uses after a line of '=' and ``MSG: pkg/Name``), as a ROS 2 reader would."""
    for part in re.split(r"\n=+\n", msgdef):
        if part.startswith("MSG: "):
            head, _, part = part.partition("\n")
            pkg, _, base = head[5:].strip().partition("/")
            name = f"{pkg}/msg/{base}"
        store.register(get_types_from_msg(part, name))


def _close(a, b):
    if isinstance(a, dict):
        return set(a) == set(b) and all(_close(a[k], b[k]) for k in a)
    if isinstance(a, list | tuple | bytes):
        return len(a) == len(b) and all(_close(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float):
        return (math.isinf(a) and math.isinf(b)) or math.isclose(a, b, rel_tol=1e-6, abs_tol=1e-9)
    return a == b


def _rosbags_plain(msg):
    if hasattr(msg, "__msgtype__"):
        return {f.name: _rosbags_plain(getattr(msg, f.name)) for f in dataclasses.fields(msg)
                if f.name != "__msgtype__"}
    if hasattr(msg, "tolist"):
        return msg.tolist()
    if isinstance(msg, list):
        return [_rosbags_plain(v) for v in msg]
    return msg


def _mcap_plain(msg, fields):
    if isinstance(fields, dict):
        return {k: _mcap_plain(getattr(msg, k), v) for k, v in fields.items()}
    if isinstance(fields, list | bytes):
        return [_mcap_plain(m, f) for m, f in zip(list(msg), list(fields), strict=True)]
    return msg


def test_export_ros2_is_read_by_rosbags_and_mcap_ros2_with_equal_values(recording, tmp_path,
                                                                        capsys):
    path, sent = recording
    bag = tmp_path / "bag"
    assert main(["export", str(path), "--ros2", "-o", str(bag)]) == 0
    assert "rosbag2" in capsys.readouterr().out
    expected = _expected(sent)
    assert {t for _, t, _, _ in expected} == {
        "nav_msgs/msg/OccupancyGrid", "geometry_msgs/msg/PoseStamped", "tf2_msgs/msg/TFMessage",
        "sensor_msgs/msg/LaserScan", "nav_msgs/msg/Path", "twinfleet_msgs/msg/RobotPose",
        "twinfleet_msgs/msg/Path"}
    types = fleet_interfaces(RosTypes()).types  # the by-fields types registered too

    # rosbags' reader: types, counts, hashes, QoS, values
    store = get_typestore(Stores.ROS2_JAZZY)
    with Reader(bag) as reader:
        conns = {c.topic: c for c in reader.connections}
        assert {t: c.msgtype for t, c in conns.items()} == {t: ty for t, ty, _, _ in expected}
        for topic, conn in conns.items():
            assert conn.msgcount == sum(1 for t, _, _, _ in expected if t == topic)
            assert conn.digest == types.type_hash(conn.msgtype)
            if not conn.msgtype.startswith("twinfleet_msgs/"):
                continue  # the reader's own store knows the standard types
            register_msgdef(store, conn.msgdef.data, conn.msgtype)
        assert conns["/map"].ext.offered_qos_profiles[0].durability.name == "TRANSIENT_LOCAL"
        got = [(c.topic, c.msgtype, _rosbags_plain(store.deserialize_cdr(raw, c.msgtype)), t)
               for c, t, raw in reader.messages()]
    assert len(got) == len(expected)
    for (topic, ros_type, fields, ns), (t2, ty2, value, t) in zip(expected, got, strict=True):
        assert (topic, ros_type, ns) == (t2, ty2, t)  # fleet time, not the wall clock
        assert _close(types.decode(ros_type, types.encode(ros_type, fields)), value), topic

    # mcap-ros2-support: the MCAP inside, profile ros2, ros2msg schemas, cdr
    (mcap_file,) = bag.glob("*.mcap")
    with mcap_file.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        decoded = list(reader.iter_decoded_messages(log_time_order=True))
    assert {s.encoding for s, *_ in decoded} == {"ros2msg"}
    assert {c.message_encoding for _, c, *_ in decoded} == {"cdr"}
    for (topic, ros_type, fields, _), (schema, channel, _m, msg) in zip(expected, decoded,
                                                                      strict=True):
        assert (channel.topic, schema.name) == (topic, ros_type)
        ours = types.decode(ros_type, types.encode(ros_type, fields))
        assert _close(ours, _mcap_plain(msg, ours)), topic

    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["storage_identifier"] == "mcap" and meta["message_count"] == len(expected)


def test_bag_info_reads_the_folder_and_refuses_others(recording, tmp_path, capsys):
    path, _ = recording
    bag = tmp_path / "bag"
    assert main(["export", str(path), "--ros2", "-o", str(bag)]) == 0
    capsys.readouterr()
    assert main(["bag", "info", str(bag)]) == 0
    text = capsys.readouterr().out
    assert "nav_msgs/msg/OccupancyGrid" in text and "Messages:          23" in text
    assert main(["bag", "info", str(tmp_path)]) == 2
    assert "not a rosbag2 bag" in capsys.readouterr().err
    assert main(["export", str(path), "--ros2", "-o", str(bag)]) == 2
    assert "exists already" in capsys.readouterr().err


POSE_SCHEMA = {"type": "object", "required": ["x", "name", "trail"], "properties": {
    "x": {"type": "number"}, "name": {"type": "string"},
    "trail": {"type": "array", "items": {"type": "array", "prefixItems": [
        {"type": "integer"}, {"type": "integer"}], "minItems": 2, "maxItems": 2}}}}


@pytest.fixture
def own_types(tmp_path):
    """A recording of a fleet's own type that this process never imported (its schema is
    the recording's), on a topic at a 100 ms fleet period recorded 20 ms apart."""
    path = tmp_path / "own.mcap"
    rec = McapRecorder(path.open("wb"))
    rec.known_schemas["turtle_msgs/Pose"] = POSE_SCHEMA
    rec.metadata({"fleet": "turtle"})
    for seq in range(1, 6):
        rec.write("twinfleet/turtle/pose", msgpack.packb(
            {"type": "turtle_msgs/Pose", "stamp_ms": 100 * seq, "seq": seq, "sender": "t1",
             "data": {"x": 0.5 * seq, "name": "t1", "trail": [[seq, 2]]}}))
        rec.write("twinfleet/turtle/chatter", encode(String(f"hi {seq}"), seq=seq,
                                                       stamp_ms=100 * seq))
        time.sleep(0.02)
    rec.close()
    return path


def test_a_fleets_own_types_need_no_mapping_and_no_import(own_types, tmp_path, capsys):
    bag = tmp_path / "bag"
    assert main(["export", str(own_types), "--ros2", "-o", str(bag)]) == 0
    assert "via no mapping, stamped with fleet time" in capsys.readouterr().out
    store = get_typestore(Stores.ROS2_JAZZY)
    with Reader(bag) as reader:
        conns = {c.topic: c for c in reader.connections}
        assert {t: (c.msgtype, c.msgcount) for t, c in conns.items()} == {
            "/pose": ("turtle_msgs/msg/Pose", 5), "/chatter": ("std_msgs/msg/String", 5)}
        register_msgdef(store, conns["/pose"].msgdef.data, "turtle_msgs/msg/Pose")
        got = [(c.topic, t, store.deserialize_cdr(raw, c.msgtype)) for c, t, raw in
               reader.messages()]
    poses = [(t, m.x, m.name, m.trail[0].values.tolist()) for topic, t, m in got
             if topic == "/pose"]
    assert poses == [(100_000_000 * k, 0.5 * k, "t1", [k, 2]) for k in range(1, 6)]
    assert [m.data for topic, _, m in got if topic == "/chatter"] == [f"hi {k}"
                                                                    for k in range(1, 6)]


def test_a_mapping_module_in_the_working_directory_needs_no_pythonpath(own_types, tmp_path,
                                                                       monkeypatch, capsys):
    (tmp_path / "turtle_bag_map.py").write_text(
        "class Mapping:\n    latched = frozenset()\n    mapped_types = frozenset()\n"
        "    def outbound(self, topic, type_name, data, stamp_ms):\n        return ()\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", ".", str(tmp_path))])
    assert main(["export", str(own_types), "--ros2", "-o", str(tmp_path / "bag"),
                 "--ros2-mapping", "turtle_bag_map:Mapping"]) == 0
    assert "via turtle_bag_map:Mapping" in capsys.readouterr().out
