"""The rclpy anchor of benchmarks/runtime_overhead.py: the same measurements in real ROS 2.

rclpy (Jazzy, from the package index: ``ros-jazzy-rclpy``, ``ros-jazzy-rmw-fastrtps-cpp``;
no ROS installation) in two processes on this machine, discovery kept on the host
(``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``): an *echo* node re-publishes each
``/bench/ping`` on ``/bench/pong``; a *ping* node measures round trips, one message in
flight, one-way = RTT / 2. Then the ping node floods ``/bench/flood`` back to back for
``--flood-s`` and the echo node counts what it received between its first sample and the
end marker. The messages are ``std_msgs/msg/UInt8MultiArray`` carrying the same
application payloads as the twinfleet measurement (64 B, 4 KiB); QoS reliable, KEEP_LAST
1000, volatile; a single-threaded executor spun by hand on each side.

`measure(size, rounds, warmup, flood_s)` runs one pair and returns
``{"p50_us", "p99_us", "msg_per_s", "sent", "received"}``; `available()` says whether
rclpy imports here. Run alone: ``python benchmarks/rclpy_anchor.py [--size 64]``.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import statistics
import subprocess
import sys
import time
from typing import Any

END = b"end"


def available() -> bool:
    """True when rclpy and std_msgs can be imported (the ros-jazzy-* packages)."""
    return all(importlib.util.find_spec(m) is not None for m in ("rclpy", "std_msgs"))


def _env() -> dict[str, str]:
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", PYTHONUNBUFFERED="1")
    env.pop("ROS_LOCALHOST_ONLY", None)  # deprecated in Jazzy: it would override the range
    env.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    env.setdefault("ROS_DOMAIN_ID", str(100 + os.getpid() % 100))  # apart from other runs
    return env


def _qos() -> Any:
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(depth=1000, history=HistoryPolicy.KEEP_LAST,
                      reliability=ReliabilityPolicy.RELIABLE)


def _echo(deadline_s: float) -> None:
    import rclpy
    from std_msgs.msg import String, UInt8MultiArray

    rclpy.init()
    node = rclpy.create_node("bench_echo")
    pong = node.create_publisher(UInt8MultiArray, "/bench/pong", _qos())
    result = node.create_publisher(String, "/bench/result", _qos())
    flood = {"n": 0, "first": 0}

    def on_ping(msg: Any) -> None:
        pong.publish(msg)

    def on_flood(msg: Any) -> None:
        if bytes(msg.data) == END:
            span = (time.perf_counter_ns() - flood["first"]) / 1e9
            result.publish(String(data=json.dumps({"received": flood["n"], "span_s": span})))
            return
        if flood["n"] == 0:
            flood["first"] = time.perf_counter_ns()
        flood["n"] += 1

    node.create_subscription(UInt8MultiArray, "/bench/ping", on_ping, _qos())
    node.create_subscription(UInt8MultiArray, "/bench/flood", on_flood, _qos())
    end = time.monotonic() + deadline_s
    while time.monotonic() < end and rclpy.ok():
        rclpy.spin_once(node, timeout_sec=0.05)
    rclpy.shutdown()


def _ping(size: int, rounds: int, warmup: int, flood_s: float) -> dict[str, Any]:
    import rclpy
    from std_msgs.msg import String, UInt8MultiArray

    rclpy.init()
    node = rclpy.create_node("bench_ping")
    ping = node.create_publisher(UInt8MultiArray, "/bench/ping", _qos())
    flood = node.create_publisher(UInt8MultiArray, "/bench/flood", _qos())
    got: list[Any] = []
    node.create_subscription(UInt8MultiArray, "/bench/pong", lambda m: got.append(1), _qos())
    node.create_subscription(String, "/bench/result", lambda m: got.append(m.data), _qos())
    msg = UInt8MultiArray(data=bytes(size))
    while ping.get_subscription_count() == 0 or flood.get_subscription_count() == 0 or \
            node.count_publishers("/bench/pong") == 0:
        rclpy.spin_once(node, timeout_sec=0.05)
    time.sleep(0.5)  # matched both ways: let discovery settle
    one_way = []
    for i in range(rounds + warmup):
        got.clear()
        start = time.perf_counter_ns()
        ping.publish(msg)
        while not got:
            rclpy.spin_once(node, timeout_sec=1.0)
        if i >= warmup:
            one_way.append((time.perf_counter_ns() - start) / 2000)
    got.clear()
    sent, end = 0, time.monotonic() + flood_s
    while time.monotonic() < end:
        flood.publish(msg)
        sent += 1
    flood.publish(UInt8MultiArray(data=END))
    while not any(isinstance(g, str) for g in got):
        rclpy.spin_once(node, timeout_sec=1.0)
    report = json.loads(next(g for g in got if isinstance(g, str)))
    rclpy.shutdown()
    ordered = sorted(one_way)
    return {"p50_us": round(statistics.median(ordered), 1),
            "p99_us": round(ordered[int(0.99 * (len(ordered) - 1))], 1),
            "msg_per_s": round(report["received"] / max(report["span_s"], 1e-9)),
            "sent": sent, "received": report["received"]}


def measure(size: int, *, rounds: int = 2000, warmup: int = 200, flood_s: float = 0.6,
            timeout_s: float = 60.0) -> dict[str, Any]:
    """One echo/ping process pair; the ping side's figures."""
    me = [sys.executable, __file__]
    echo = subprocess.Popen([*me, "--role", "echo", "--deadline", str(timeout_s)], env=_env())
    try:
        out = subprocess.run([*me, "--role", "ping", "--size", str(size), "--rounds", str(rounds),
                              "--warmup", str(warmup), "--flood-s", str(flood_s)],
                             env=_env(), capture_output=True, text=True, timeout=timeout_s,
                             check=True).stdout
        return json.loads(out.strip().splitlines()[-1])
    finally:
        echo.kill()
        echo.wait()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--role", choices=("echo", "ping"), default=None)
    p.add_argument("--size", type=int, default=64, help="payload bytes (default: 64)")
    p.add_argument("--rounds", type=int, default=2000, help="ping-pong rounds counted")
    p.add_argument("--warmup", type=int, default=200, help="first rounds not counted")
    p.add_argument("--flood-s", type=float, default=0.6, help="seconds of flood")
    p.add_argument("--deadline", type=float, default=60.0, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.role == "echo":
        _echo(args.deadline)
    elif args.role == "ping":
        print(json.dumps(_ping(args.size, args.rounds, args.warmup, args.flood_s)), flush=True)
    else:
        print(json.dumps(measure(args.size, rounds=args.rounds, warmup=args.warmup,
                                 flood_s=args.flood_s)))


if __name__ == "__main__":
    main()
