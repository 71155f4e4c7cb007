"""`twinfleet node list` / `topic list -t -v` / `topic echo` with ``--ros2-domain``: ROS 2
nodes made by zenoh-ros2-sdk (not ours, its own process) behind a router on 127.0.0.1 are
listed, marked (ros2), with their topics' types, and what they publish is decoded; another
domain's are not listed."""

from __future__ import annotations

import contextlib
import subprocess
import sys
from collections.abc import Iterator

import pytest
import zenoh

from tests.support import child_env, pick_free_port
from twinfleet.cli import main
from twinfleet.ros2.graph_list import RosGraph
from twinfleet.runtime.host.zenoh_transport import zenoh_config

pytestmark = [pytest.mark.slow, pytest.mark.timeout(60)]
# The end of each peer script: call speak(i) every PERIOD s until stdin closes, then close.
UNTIL_STDIN_CLOSES = """
import threading
stop = threading.Event()
def talk():
    i = 0
    while not stop.wait(PERIOD):
        speak(i)
        i += 1
talker = threading.Thread(target=talk)
talker.start()
print("ready", flush=True)
sys.stdin.read()
stop.set()
talker.join()
for endpoint in ENDPOINTS:
    endpoint.close()
"""
PEER = """
import sys
from pathlib import Path
from zenoh_ros2_sdk.message_registry import get_registry
from zenoh_ros2_sdk.publisher import ROS2Publisher
from zenoh_ros2_sdk.subscriber import ROS2Subscriber
get_registry(str(Path(sys.prefix) / "share"))
port = int(sys.argv[1])
pub = ROS2Publisher("/chatter", "std_msgs/msg/String", node_name="talker", router_port=port)
sub = ROS2Subscriber("/chatter", "std_msgs/msg/String", node_name="listener",
                     router_port=port, callback=lambda m: None)
PERIOD, ENDPOINTS = 0.05, (sub, pub)
def speak(i):
    pub.publish(data=f"hello {i}")
""" + UNTIL_STDIN_CLOSES


@contextlib.contextmanager
def peer_on_router(script: str, *args: str) -> Iterator[list[str]]:
    """A Zenoh router on a free port and a zenoh-ros2-sdk peer running `script` there (it
    prints "ready"); the monitors' connection arguments; both stopped on the way out."""
    port = pick_free_port()
    router = zenoh.open(zenoh_config(listen=[f"tcp/127.0.0.1:{port}"], mode="router"))
    env = dict(child_env(), ZENOH_CONFIG_OVERRIDE="scouting/multicast/enabled=false")
    peer = subprocess.Popen([sys.executable, "-c", script, str(port), *args],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)
    try:
        assert peer.stdout is not None and peer.stdout.readline().strip() == "ready"
        yield ["--connect", f"tcp/127.0.0.1:{port}"]
    finally:
        assert peer.stdin is not None
        peer.stdin.close()
        try:
            peer.wait(timeout=10)
        except subprocess.TimeoutExpired:
            peer.kill()
        router.close()


def test_node_and_topic_list_show_ros2_nodes_on_the_same_network(capsys):
    with peer_on_router(PEER) as ep:
        assert main(["node", "list", *ep, "--ros2-domain", "0"]) == 0
        nodes = capsys.readouterr().out.splitlines()
        assert "/talker  (ros2)" in nodes and "/listener  (ros2)" in nodes
        assert main(["topic", "list", "-t", "-v", *ep, "--ros2-domain", "0"]) == 0
        out = capsys.readouterr().out
        assert ("/chatter [std_msgs/msg/String]  [publishers: /talker; subscribers: /listener]"
                "  (ros2)") in out.splitlines()
        assert main(["node", "list", *ep, "--ros2-domain", "7"]) == 0
        assert "(ros2)" not in capsys.readouterr().out
        assert main(["topic", "echo", "/chatter", *ep, "--ros2-domain", "0", "--count", "2",
                     "--duration", "10"]) == 0
        docs = [d for d in capsys.readouterr().out.split("---") if d.strip()]
        assert len(docs) == 2 and all(d.strip().startswith("data: hello ") for d in docs)


def test_tokens_that_are_not_rmw_zenohs_are_skipped():
    graph = RosGraph.of(["@ros2_lv/0/zid/1/1/NN/%/%/talker", "@ros2_lv/0/broken",
                         "twinfleet/f/@node/r1"])
    assert graph.nodes == {"/talker"} and not graph.types


ODD_PEER = """
import sys
from zenoh_ros2_sdk.message_registry import get_registry
from zenoh_ros2_sdk.publisher import ROS2Publisher
get_registry(sys.argv[2])
pub = ROS2Publisher("/odd", "echo_test_msgs/msg/Odd", node_name="odd", router_port=int(sys.argv[1]))
PERIOD, ENDPOINTS = 0.02, (pub,)
def speak(i):
    pub.publish(value=7)
""" + UNTIL_STDIN_CLOSES


def test_echo_once_of_a_type_not_decodable_here_is_one_line_and_exit_1(tmp_path, capsys):
    # a type only the peer knows (its .msg written here): many samples, one line, then the end
    msg = tmp_path / "echo_test_msgs" / "msg"
    msg.mkdir(parents=True)
    (msg / "Odd.msg").write_text("int32 value\n")
    with peer_on_router(ODD_PEER, str(tmp_path)) as ep:
        assert main(["topic", "echo", "/odd", *ep, "--ros2-domain", "0", "--once",
                     "--duration", "20"]) == 1
        captured = capsys.readouterr()
        assert captured.out == ""
        (line,) = captured.err.splitlines()
        assert line.startswith("/odd: a sample is not decodable here (") and \
            "echo_test_msgs/msg/Odd" in line, line
        assert main(["topic", "echo", "/odd", *ep, "--ros2-domain", "0", "--duration", "1"]) == 1
        lines = capsys.readouterr().err.splitlines()
        assert len(lines) == 2 and lines[1].startswith("/odd: ") and \
            lines[1].endswith(" samples were not decodable here"), lines
