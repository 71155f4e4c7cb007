"""The ROS 2 verbs against live fleets, found without --connect.

Each test module run has its own fleet registry (a private XDG_RUNTIME_DIR,
as a desktop session gives every user); the launcher registers its fleet
there and every monitor command below runs with *no* --connect and no
TWINFLEET_* variable. One C1a fleet (time scale 1, without the run report that ends it
once every robot has arrived) serves the verbs; a demo fleet launched with parameter overrides joins it for
the launch-override, pub and call tests, which also check that two running
fleets make a bare `node list` ask for --fleet.
"""

from __future__ import annotations

import re
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml
from itest_support import ROOT, launch_in, poll, run_cli_in, stop_launch

pytestmark = [pytest.mark.slow, pytest.mark.timeout(120)]

ROBOTS = ["r1", "r2", "r3", "r4", "r5"]


@pytest.fixture(scope="module")
def runtime_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("xdg-runtime")


tf = run_cli_in


def endless_c1a(where: Path) -> Path:
    """A copy of C1a without its run report, which ends the run once every robot has
    arrived (a minute at time scale 1: on a busy machine, before this module's last test);
    without it the fleet runs on to --timeout."""
    ok(run_cli_in(where, "examples", "--copy", "c1a", str(where)))
    path = where / "c1a.yaml"
    doc = yaml.safe_load(path.read_text())
    del doc["live"]["report"]
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


@pytest.fixture(scope="module")
def c1a(runtime_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    where = tmp_path_factory.mktemp("c1a")
    log = where / "fleet.log"
    proc = launch_in(runtime_dir, log, str(endless_c1a(where)), "--time-scale", "1",
                     "--timeout", "600")
    try:
        assert poll(lambda: log.read_text().count("] t=") >= 6 or proc.poll() is not None, 40)
        assert proc.poll() is None, log.read_text()
        yield log
    finally:
        stop_launch(proc)


@pytest.fixture(scope="module")
def demo(runtime_dir: Path, c1a: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    log = tmp_path_factory.mktemp("demo") / "fleet.log"
    scenario = str(ROOT / "twinfleet" / "launch" / "demo.yaml")
    proc = launch_in(runtime_dir, log, scenario, "talker.period_ms:=250", "--param",
                   "caller.period_ms=300", "--timeout", "600")
    try:
        assert poll(lambda: log.read_text().count("started") >= 4 or proc.poll() is not None, 40)
        assert proc.poll() is None, log.read_text()
        yield log
    finally:
        stop_launch(proc)


def ok(result: subprocess.CompletedProcess[str]) -> str:
    assert result.returncode == 0, result.stdout + result.stderr
    assert "Traceback" not in result.stderr
    return result.stdout


def test_node_list_and_echo_poses_without_connect(runtime_dir, c1a):
    # One fleet running: found with no --connect and no TWINFLEET_* variable.
    assert ok(tf(runtime_dir, "node", "list")).split() == ["/map_server", *(f"/{r}" for r in ROBOTS)]
    # as ros2 prints them: the message's fields; --full: the envelope around them
    [pose] = [d for d in yaml.safe_load_all(ok(tf(runtime_dir, "topic", "echo", "/poses", "--once"))) if d]
    assert pose["robot"] in ROBOTS and "type" not in pose
    [env] = [d for d in yaml.safe_load_all(ok(tf(runtime_dir, "topic", "echo", "/poses", "--once",
                                                  "--full"))) if d]
    assert env["type"] == "twinfleet_msgs/RobotPose" and env["data"]["robot"] in ROBOTS
    assert {"stamp_ms", "seq", "sender"} <= set(env)


def test_echo_map_once_for_a_late_joiner(runtime_dir, c1a):
    # The map server publishes /map once, at its start; the robots are already moving
    # (the fixture waited for every node's start line), so this echo joins late.
    ok(tf(runtime_dir, "topic", "echo", "/poses", "--once"))
    [doc] = [d for d in yaml.safe_load_all(ok(tf(runtime_dir, "topic", "echo", "/map", "--once"))) if d]
    assert (doc["width"], doc["height"]) == (50, 50)


def test_echo_field(runtime_dir, c1a):
    out = ok(tf(runtime_dir, "topic", "echo", "/poses", "--once", "--field", "cell"))
    cell = yaml.safe_load(out.split("---")[0])
    assert isinstance(cell, list) and len(cell) == 2 and all(isinstance(v, int) for v in cell)
    first = ok(tf(runtime_dir, "topic", "echo", "/poses", "--once", "--field", "cell.0"))
    assert isinstance(yaml.safe_load(first.split("---")[0]), int)
    bad = tf(runtime_dir, "topic", "echo", "/poses", "--once", "--field", "nope")
    assert bad.returncode == 2 and "no field 'nope'" in bad.stderr
    sender = ok(tf(runtime_dir, "topic", "echo", "/poses", "--once", "--full", "--field", "sender"))
    assert sender.split("\n")[0] in ROBOTS


def test_topic_list_with_types_matches_the_readme(runtime_dir, c1a):
    out = ok(tf(runtime_dir, "topic", "list", "-t"))
    listed = dict(re.findall(r"^(\S+) \[(\S+)\]$", out, re.M))
    assert listed["/map"] == "twinfleet_msgs/OccupancyGrid"
    assert listed["/poses"] == "twinfleet_msgs/RobotPose"
    assert listed["/r1/scan"] == "twinfleet_msgs/ObstacleScan"
    # nobody publishes a goal: its type is the robots' subscription's, before any message
    assert listed["/r1/goal"] == "twinfleet_msgs/Goal" and "no message yet" not in out, out
    readme = (ROOT / "README.md").read_text()
    block = readme.split("<!-- topics:c1a -->")[1].split("<!-- /topics -->")[0]
    documented = dict(re.findall(r"^\| `(\S+)` \| `(\S+)` \|", block, re.M))
    expanded = {t.replace("<robot>", r): k for t, k in documented.items() for r in ROBOTS}
    for topic, kind in listed.items():
        assert expanded.get(topic) == kind, f"{topic} [{kind}] is not in the README's topic list"
    missing = set(expanded) - set(listed)
    assert missing <= {"/collisions", "/twinfleet/shutdown", "/violations"}, missing


def test_topic_info_and_type(runtime_dir, c1a):
    out = ok(tf(runtime_dir, "topic", "info", "/poses", "-v"))
    assert "Type: twinfleet_msgs/RobotPose" in out
    assert "Publisher count: 5" in out and "Subscription count: 1" in out
    subscription = out.split("Endpoint type: SUBSCRIPTION", 1)[1]  # the map server's
    # the map server keeps one pose of every robot it may track (nodes.map_server.MAX_ROBOTS)
    assert "Node name: map_server" in out and "History (Depth): KEEP_LAST (100)" in subscription
    latched = ok(tf(runtime_dir, "topic", "info", "/map", "-v"))
    assert "Durability: TRANSIENT_LOCAL" in latched
    assert ok(tf(runtime_dir, "topic", "type", "/map")).strip() == "twinfleet_msgs/OccupancyGrid"


def test_node_info(runtime_dir, c1a):
    out = ok(tf(runtime_dir, "node", "info", "r1"))
    assert out.startswith("/r1  (twinfleet.nodes.robot:Robot")
    subs = out.split("Subscribers:")[1].split("Publishers:")[0]
    assert "/r1/scan: twinfleet_msgs/ObstacleScan" in subs
    assert "/poses: twinfleet_msgs/RobotPose" in out.split("Publishers:")[1]
    assert "speed: 0.5" in out.split("Parameters:")[1]
    clients = out.split("Service Clients:")[1].split("Timers:")[0]
    assert clients.split() == ["/generate_path"]  # its ctx.call, read from its code
    assert "update_moving_status: one-shot, set by ctx.after" in out.split("Timers:")[1]
    assert "/generate_path" in ok(tf(runtime_dir, "node", "info", "map_server"))


def test_param_list_and_get(runtime_dir, c1a):
    out = ok(tf(runtime_dir, "param", "list", "r2"))
    assert out.startswith("/r2:") and "  speed" in out and "  max_wait_ms" in out
    assert ok(tf(runtime_dir, "param", "get", "r2", "speed")).strip() == "Double value is: 0.7"
    assert ok(tf(runtime_dir, "param", "get", "r2", "goal")).strip() == "List value is: [45, 35]"
    bad = tf(runtime_dir, "param", "get", "r2", "sped")
    assert bad.returncode == 2 and "no parameter 'sped'" in bad.stderr


def test_interface_show_reads_the_fleets_schemas(runtime_dir, c1a):
    out = ok(tf(runtime_dir, "interface", "show", "twinfleet_msgs/msg/RobotPose"))
    assert out.splitlines()[0].startswith("# twinfleet_msgs/RobotPose (served by ")
    assert "int64[2] cell" in out and "bool done  # optional" in out
    assert "twinfleet_msgs/Collision" in ok(tf(runtime_dir, "interface", "list"))


def test_param_dump_and_set(runtime_dir, c1a):
    dumped = yaml.safe_load(ok(tf(runtime_dir, "param", "dump", "r2")))
    assert dumped["/r2"]["ros__parameters"]["speed"] == 0.7
    assert dumped["/r2"]["ros__parameters"]["goal"] == [45, 35]
    refused = tf(runtime_dir, "param", "set", "r2", "speed", "0.4")
    assert refused.returncode == 2 and len(refused.stderr.strip().splitlines()) == 1
    assert "fixed for a launch" in refused.stderr and "r2.speed:=0.4" in refused.stderr


def test_bag_info_of_a_recording_of_the_running_fleet(runtime_dir, c1a, tmp_path):
    bag = tmp_path / "joined.mcap"
    ok(tf(runtime_dir, "record", "--duration", "2", "-o", str(bag)))
    out = ok(tf(runtime_dir, "bag", "info", str(bag)))
    counts = {t: int(n) for t, n in re.findall(r"^  (\S+)\s+type: \S+\s+count:\s+(\d+)", out, re.M)}
    assert counts.get("/poses", 0) >= 5 and "Duration:" in out and "Fleet:             c1a" in out
    assert "twinfleet_msgs/RobotPose (jsonschema)" in out


def test_launch_overrides_and_two_fleets(runtime_dir, demo):
    several = tf(runtime_dir, "node", "list")
    assert several.returncode == 2 and len(several.stderr.strip().splitlines()) == 1
    assert "2 fleets are running" in several.stderr and "--fleet NAME" in several.stderr
    assert ok(tf(runtime_dir, "param", "get", "talker", "period_ms", "--fleet", "demo")).strip() \
        == "Integer value is: 250"
    assert ok(tf(runtime_dir, "param", "get", "caller", "period_ms", "--fleet", "demo")).strip() \
        == "Integer value is: 300"


def test_pub_takes_a_ros_type_name_and_warns_without_subscriber(runtime_dir, demo):
    heard = ok(tf(runtime_dir, "topic", "pub", "/chatter", "std_msgs/msg/String",
                  "{data: ros-style}", "--fleet", "demo"))
    assert "published #1 on /chatter: std_msgs/String" in heard
    assert poll(lambda: "heard data='ros-style'" in demo.read_text(), 10), demo.read_text()[-2000:]
    lonely = tf(runtime_dir, "topic", "pub", "/nobody_listens", "std_msgs/String", "{data: x}",
                "--fleet", "demo")
    assert lonely.returncode == 0 and "warning: no subscriber on /nobody_listens" in lonely.stderr
    quiet = tf(runtime_dir, "topic", "pub", "/chatter", "std_msgs/String", "{data: y}",
               "--fleet", "demo")
    assert "warning" not in quiet.stderr


def test_service_call_with_a_ros_service_type(runtime_dir, demo):
    out = ok(tf(runtime_dir, "service", "call", "/add_two_ints",
                "example_interfaces/srv/AddTwoInts", "{a: 2, b: 40}", "--fleet", "demo"))
    assert out.strip() == "sum: 42"  # the reply's fields, as ros2 prints them
    full = ok(tf(runtime_dir, "service", "call", "/add_two_ints",
                 "example_interfaces/srv/AddTwoInts", "{a: 2, b: 40}", "--fleet", "demo", "--full"))
    assert "data: {sum: 42}" in full and "type: example_interfaces/AddTwoInts_Response" in full


def test_pub_once_rate_and_times_and_echo_of_a_bare_field(runtime_dir, demo):
    for once in ("--once", "-1"):
        out = ok(tf(runtime_dir, "topic", "pub", once, "/chatter", "std_msgs/String",
                    "{data: once}", "--fleet", "demo"))
        assert out.count("published #") == 1, out
    times = ok(tf(runtime_dir, "topic", "pub", "/chatter", "std_msgs/String", "{data: t}",
                  "-r", "20", "-t", "3", "--fleet", "demo"))
    assert [line.split()[1] for line in times.splitlines() if line.startswith("published")] \
        == ["#1", "#2", "#3"], times
    text = ok(tf(runtime_dir, "topic", "echo", "/chatter", "--once", "--field", "data",
                 "--fleet", "demo"))
    value = text.split("\n---")[0].strip()
    assert value and not value.startswith(("data:", "{")), text  # the bare value


def test_service_list_with_types_and_service_type(runtime_dir, demo):
    listed = ok(tf(runtime_dir, "service", "list", "-t", "--fleet", "demo"))
    assert "/add_two_ints [example_interfaces/srv/AddTwoInts]" in listed
    one = ok(tf(runtime_dir, "service", "type", "/add_two_ints", "--fleet", "demo"))
    assert one.strip() == "example_interfaces/srv/AddTwoInts"
    shown = ok(tf(runtime_dir, "interface", "show", "example_interfaces/srv/AddTwoInts",
                  "--fleet", "demo"))
    request, reply = shown.split("\n---\n")
    assert "int64 a" in request and "int64 b" in request and "int64 sum" in reply
    services = ok(tf(runtime_dir, "interface", "list", "--fleet", "demo")).split("Services:")[1]
    assert "example_interfaces/srv/AddTwoInts" in services.split()
    caller = ok(tf(runtime_dir, "node", "info", "caller", "--fleet", "demo"))
    assert caller.split("Service Clients:")[1].split("Timers:")[0].split() == ["/add_two_ints"]
    talker = ok(tf(runtime_dir, "node", "info", "talker", "--fleet", "demo"))
    assert "tick: one-shot, set by ctx.after" in talker
    missing = tf(runtime_dir, "service", "type", "/add_three_ints", "--fleet", "demo")
    assert missing.returncode == 2 and "no running node serves it" in missing.stderr


def test_mistyped_topic_and_fleet_are_reported(runtime_dir, c1a):
    echo = tf(runtime_dir, "topic", "echo", "/posse", "--once", "--fleet", "c1a")
    assert echo.returncode == 2 and "no node publishes or subscribes /posse" in echo.stderr
    fleet = tf(runtime_dir, "topic", "echo", "/poses", "--once", "--fleet", "c1b")
    assert fleet.returncode == 2 and "no fleet named 'c1b' is running" in fleet.stderr


@pytest.mark.offline  # help texts: the commands end by themselves
def test_every_verb_has_help(runtime_dir):
    for verb in (["node", "info"], ["topic", "info"], ["topic", "type"], ["topic", "echo"],
                 ["service", "type"],
                 ["param", "list"], ["param", "get"], ["interface", "show"], ["bag", "info"]):
        text = ok(tf(runtime_dir, *verb, "--help"))
        assert "usage: twinfleet " + " ".join(verb) in text
    assert ok(tf(runtime_dir, "--version")).startswith("twinfleet ")
    assert "--query-timeout" not in ok(tf(runtime_dir, "view", "--help"))
