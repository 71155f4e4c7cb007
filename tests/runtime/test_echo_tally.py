"""`topic echo` on a fleet topic: a sample that is not a twinfleet envelope is one line on
stderr (the first of its reason), counts toward --once/--count, and makes the exit code 1."""

from __future__ import annotations

import io

import msgpack

from twinfleet.runtime.tools.monitor.data_verbs import EchoTally, _print_sample


def test_an_undecodable_sample_is_one_line_counted_and_exit_1():
    out, err = io.StringIO(), io.StringIO()
    tally = EchoTally("/chatter", err)
    good = msgpack.packb({"type": "std_msgs/String", "data": {"data": "hi"}})
    for payload in (b"\xc1 garbage", good, b"\xc1 garbage"):
        _print_sample(out, payload, None, "/chatter", False, tally)
    assert (tally.shown, tally.seen) == (1, 3)
    assert out.getvalue() == "data: hi\n---\n"
    (line,) = err.getvalue().splitlines()
    assert line.startswith("/chatter: a sample is not decodable here (not a twinfleet envelope")
    assert tally.exit_code() == 1
    assert err.getvalue().splitlines()[-1] == "/chatter: 2 samples were not decodable here"
    assert EchoTally("/x", io.StringIO()).exit_code() == 0
