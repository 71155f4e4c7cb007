"""`twinfleet export run.mcap --ros2 -o BAG/`: a rosbag2 folder that two readers that are
not ours (rosbags' rosbag2 reader, mcap-ros2-support's decoder) read with the recording's
types, counts, timestamps and values."""

from __future__ import annotations

import dataclasses
import math

import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore

from twinfleet.cli import main
from twinfleet.nodes.msgs import ObstacleScan, OccupancyGrid, Path, RobotPose
from twinfleet.nodes.ros2_mapping import RobotRos2Mapping
from twinfleet.ros2.cdr import RosTypes
from twinfleet.runtime.contract.messages import encode
from twinfleet.runtime.tools.record.recorder import McapRecorder

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
    """What the mapping makes of the recording, in order: (topic, type, fields)."""
    table = RobotRos2Mapping()
    out = []
    for seq, (key, msg) in enumerate(sent, 1):
        fields = {f.name: getattr(msg, f.name) for f in dataclasses.fields(msg)}
        fields = {k: list(v) if isinstance(v, tuple) else v for k, v in fields.items()}
        out += table.outbound(key.removeprefix("twinfleet/f"), msg.__message_type__, fields,
                              100 * seq)
    return out


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
    assert {t for _, t, _ in expected} == {
        "nav_msgs/msg/OccupancyGrid", "geometry_msgs/msg/PoseStamped", "tf2_msgs/msg/TFMessage",
        "sensor_msgs/msg/LaserScan", "nav_msgs/msg/Path"}
    types = RosTypes()

    # rosbags' reader: types, counts, hashes, QoS, values
    store = get_typestore(Stores.ROS2_JAZZY)
    with path.open("rb") as f:
        log_times = [m.log_time for _, _, m in make_reader(f).iter_messages(log_time_order=True)]
    with Reader(bag) as reader:
        conns = {c.topic: c for c in reader.connections}
        assert {t: c.msgtype for t, c in conns.items()} == {t: ty for t, ty, _ in expected}
        for topic, conn in conns.items():
            assert conn.msgcount == sum(1 for t, _, _ in expected if t == topic)
            assert conn.digest == types.type_hash(conn.msgtype)
        assert conns["/map"].ext.offered_qos_profiles[0].durability.name == "TRANSIENT_LOCAL"
        got = [(c.topic, c.msgtype, _rosbags_plain(store.deserialize_cdr(raw, c.msgtype)), t)
               for c, t, raw in reader.messages()]
    assert len(got) == len(expected)
    for (topic, ros_type, fields), (t2, ty2, value, _) in zip(expected, got, strict=True):
        assert (topic, ros_type) == (t2, ty2)
        assert _close(types.decode(ros_type, types.encode(ros_type, fields)), value), topic
    assert {t for *_, t in got} <= set(log_times)  # the recording's receive times

    # mcap-ros2-support: the MCAP inside, profile ros2, ros2msg schemas, cdr
    (mcap_file,) = bag.glob("*.mcap")
    with mcap_file.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        decoded = list(reader.iter_decoded_messages(log_time_order=True))
    assert {s.encoding for s, *_ in decoded} == {"ros2msg"}
    assert {c.message_encoding for _, c, *_ in decoded} == {"cdr"}
    for (topic, ros_type, fields), (schema, channel, _m, msg) in zip(expected, decoded,
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
    assert "nav_msgs/msg/OccupancyGrid" in text and "Messages:          17" in text
    assert main(["bag", "info", str(tmp_path)]) == 2
    assert "not a rosbag2 bag" in capsys.readouterr().err
    assert main(["export", str(path), "--ros2", "-o", str(bag)]) == 2
    assert "exists already" in capsys.readouterr().err
