"""Failure 2: unbounded, unchecked input.

Before: one 9-10 MB message on /poses made the map server unresponsive for
8 s; a pose at cell (NaN, inf) was accepted and produced four collisions and
a distance of inf; a string cell raised inside the handler after the state
had changed; a RobotPose on /r1/scan reached the scan handler and raised.
Now (all signed with the fleet key, so only the size and type checks stand
in the way): a sample above the topic's limit is dropped before it is copied
(``rejected_oversize``; 10 MB does not even pass the router), decoded fields
are checked against the message type (``rejected_invalid``), a message of the
wrong type is dropped (``rejected_wrong_type``), and the map server keeps
answering throughout.
"""

from __future__ import annotations

import time

import pytest

from tests.adversarial import harness as h
from twinfleet.runtime.core.guard import DEFAULT_LIMIT, sign

pytestmark = [pytest.mark.slow, pytest.mark.timeout(90)]


def pose(cell: list, seq: int) -> bytes:
    return h.envelope("twinfleet_msgs/RobotPose", {"robot": "r1", "cell": cell, "direction": 0,
                                                 "velocity": 1}, sender="r1", seq=seq)


def answer_s(session, fleet: str) -> float:
    """Seconds the map server takes to answer a path request (signed, as a robot's is)."""
    key = f"twinfleet/{fleet}/generate_path"
    payload = h.envelope("twinfleet_msgs/PathRequest", {"robot": "r9", "start": [40, 40],
                                                      "goal": [40, 45], "final": True},
                       sender="r9")
    started = time.monotonic()
    replies = list(session.get(key, payload=payload, attachment=sign(KEY[0], key, payload),
                               timeout=5.0))
    assert replies and replies[0].ok is not None, replies
    return time.monotonic() - started


KEY: list[bytes] = []


def test_oversize_invalid_and_mistyped_samples_are_refused_and_the_server_stays_responsive(
        tmp_path) -> None:
    with h.running_fleet(tmp_path, "bounded", goal=30, scale=2.0) as fleet:
        KEY[:] = [fleet.key]
        s = h.client(fleet.endpoint, fleet.login("operator"))
        try:
            h.wait_matched(s, fleet.fleet, "/poses")
            h.put(s, fleet.fleet, "/poses", b"\x00" * (10 << 20), KEY[0])  # 10 MB: the router drops it
            assert answer_s(s, fleet.fleet) < 1.0
            assert h.stats(s, fleet.fleet, "map_server", timeout=1.0) is not None
            # over the topic's limit, under the router's frame limit: the node's check drops it
            padded = h.envelope("twinfleet_msgs/RobotPose", {
                "robot": "r1" + "x" * DEFAULT_LIMIT, "cell": [25, 6], "direction": 0,
                "velocity": 1}, sender="r1", seq=2)
            assert DEFAULT_LIMIT < len(padded) < DEFAULT_LIMIT + 1024
            h.put(s, fleet.fleet, "/poses", padded, KEY[0])
            for seq, cell in enumerate(([float("nan"), float("inf")], ["a", "b"], [1, 2, 3],
                                        [True, 4]), start=3):
                h.put(s, fleet.fleet, "/poses", pose(cell, seq), KEY[0])
            h.put(s, fleet.fleet, "/r1/scan", pose([5, 6], 9), KEY[0])  # a pose where scans go
            seen = h.poll(lambda: _refusals(s, fleet.fleet), 10)
            assert seen == {"map_server": (1, 4), "r1": 1}, seen
            assert answer_s(s, fleet.fleet) < 1.0
        finally:
            s.close()
        code = fleet.wait_end(60)
        out = fleet.output()
    assert "collisions: none" in out and " inf " not in out, out[-2000:]
    assert "handler_errors=0" in out and "Traceback" not in out
    assert h.honest_result(out, code), out[-2000:]


def _refusals(session, fleet: str) -> dict | None:
    server, robot = h.stats(session, fleet, "map_server"), h.stats(session, fleet, "r1")
    if not server or not robot:
        return None
    found = {"map_server": (server["rejected_oversize"], server["rejected_invalid"]),
             "r1": robot["rejected_wrong_type"]}
    return found if found == {"map_server": (1, 4), "r1": 1} else None
