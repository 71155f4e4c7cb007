"""A recorded C1a run exported to rosbag2 holds every topic of the recording with its count,
stamped with fleet time (read with rosbags' reader, not ours): the fleet runs at time scale 5,
so its 100 ms scan period is 20 ms of wall time apart in the recording and 100 ms in the bag."""

from __future__ import annotations

import subprocess
import sys
from collections import Counter, defaultdict

import msgpack
import pytest
from mcap.reader import make_reader
from rosbags.rosbag2 import Reader

from tests.integration.itest_support import kill_all, spawned_by
from tests.support import child_env
from twinfleet.cli import main

pytestmark = [pytest.mark.slow, pytest.mark.fleet, pytest.mark.timeout(120)]


def test_a_recorded_c1a_run_is_a_bag_with_every_topic_counted_in_fleet_time(tmp_path, capsys):
    run = tmp_path / "c1a.mcap"
    with subprocess.Popen([sys.executable, "-m", "twinfleet", "record", "c1a", "--time-scale",
                           "5", "--duration", "4", "-o", str(run)], stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, text=True, env=child_env(),
                          cwd=tmp_path) as proc:
        try:
            out, _ = proc.communicate(timeout=90)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait(timeout=10)
            kill_all(spawned_by(proc.pid))
    assert run.exists(), out[-3000:]
    recorded: dict[str, list[int]] = defaultdict(list)  # topic -> fleet ns of its messages
    with run.open("rb") as f:
        for _, channel, message in make_reader(f).iter_messages(log_time_order=True):
            recorded[channel.topic].append(
                msgpack.unpackb(message.data, raw=False)["stamp_ms"] * 1_000_000)
    assert {"/map", "/poses", "/fleet_status", "/r1/scan", "/r1/status"} <= set(recorded)

    bag = tmp_path / "bag"
    assert main(["export", str(run), "--ros2", "-o", str(bag)]) == 0
    assert "left out" not in capsys.readouterr().err
    with Reader(bag) as reader:
        types: dict[str, set[str]] = defaultdict(set)
        for c in reader.connections:
            types[c.topic].add(c.msgtype)
        counts = Counter(c.topic for c, _, _ in reader.messages())
        times: dict[str, list[int]] = defaultdict(list)
        for c, t, _ in reader.messages():
            times[c.topic].append(t)
    for topic, stamps in recorded.items():
        assert len(types[topic]) == 1, (topic, types[topic])  # one type per topic
        assert counts[topic] == len(stamps), (topic, counts[topic], len(stamps))
        assert sorted(times[topic]) == sorted(stamps), topic  # the fleet's stamps
    assert types["/map"] == {"nav_msgs/msg/OccupancyGrid"}
    assert types["/r1/scan"] == {"sensor_msgs/msg/LaserScan"}
    assert types["/r1/status"] == {"twinfleet_msgs/msg/RobotStatus"}
    assert counts["/tf"] == counts["/poses"]  # the mapped views besides
    scans = sorted(times["/r1/scan"])
    gaps = {b - a for a, b in zip(scans, scans[1:], strict=False)}
    assert gaps == {100_000_000}, gaps  # the scan period in fleet time, not 20 ms of wall
