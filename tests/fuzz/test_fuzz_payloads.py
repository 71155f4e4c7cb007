"""Bad input, fuzzed: garbage samples and wrong-typed service requests from a raw Zenoh client.

One node process (`FuzzTarget`: a typed subscription and a typed service) runs
against a router in this process; a plain zenoh-python client session throws
Hypothesis-generated payloads at it: random bytes, msgpack that is not an
envelope, and envelopes with unknown types, missing or extra fields and
wrongly typed values. For every payload the test predicts, with the same
codec, what the node must do — drop and count it as undecodable, count a
handler error, or handle it — and checks the node's counters (read from its
statistics queryable) against the prediction after every batch. Every service
call must get an answer (a reply, or a "server error: ..." error) well before
its timeout, and the node must still be alive and serving at the end.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgpack
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

zenoh = pytest.importorskip("zenoh")

from tests.integration.reliability_nodes import AddReply, AddRequest, Tick  # noqa: E402
from twinfleet.runtime.contract.messages import decode, encode  # noqa: E402
from twinfleet.runtime.core.guard import Admission, Rejected, check_message  # noqa: E402
from twinfleet.runtime.fleet.launcher import free_port  # noqa: E402
from twinfleet.runtime.host.keys import KeyKind, node_key, topic_key  # noqa: E402
from twinfleet.runtime.host.zenoh_transport import zenoh_config  # noqa: E402

pytestmark = [pytest.mark.slow, pytest.mark.fleet, pytest.mark.timeout(150)]

ROOT = Path(__file__).resolve().parents[2]
FLEET = "fuzz"
TICKS = topic_key(FLEET, "/fuzz/ticks")
ADD = topic_key(FLEET, "/fuzz/add")
CALL_TIMEOUT_S = 5.0
SCENARIO = """\
name: fuzz
nodes:
  - {name: target, class: "tests.integration.reliability_nodes:FuzzTarget"}
"""

# ------------------------------------------------------------------ payloads

scalars = st.one_of(st.none(), st.booleans(), st.integers(-(2**63), 2**64 - 1),
                    st.floats(), st.text(max_size=8), st.binary(max_size=8))
keys = st.one_of(st.sampled_from(["_type", "n", "source", "blob", "a", "b", "data"]),
                 st.text(max_size=5), st.integers(-3, 3))
plain = st.recursive(scalars, lambda inner: st.lists(inner, max_size=4)
                     | st.dictionaries(keys, inner, max_size=4), max_leaves=12)
type_names = st.one_of(
    st.sampled_from(["twinfleet_test/Tick", "twinfleet_test/AddRequest", "std_msgs/String",
                     "twinfleet/NodeAlive", "no_such/Type"]),
    st.text(max_size=12), scalars)
tick_like = st.fixed_dictionaries({"source": scalars, "n": scalars},
                                  optional={"blob": scalars, "extra": scalars})
add_like = st.fixed_dictionaries({"a": scalars, "b": scalars}, optional={"c": scalars})
envelopes = st.fixed_dictionaries(
    {"type": type_names, "data": st.one_of(tick_like, add_like, plain)},
    optional={"seq": scalars, "stamp_ms": scalars, "sender": scalars})
valid = st.one_of(
    st.builds(lambda n, s: encode(Tick("fuzzer", n), seq=s, sender="fuzzer"),
              st.integers(0, 10**6), st.integers(0, 10**6)),
    st.builds(lambda a, b: encode(AddRequest(a, b), sender="fuzzer"),
              st.integers(-(2**63), 2**63), st.integers(-(2**63), 2**63)))
payloads = st.one_of(st.binary(max_size=64), plain.map(msgpack.packb),
                     envelopes.map(msgpack.packb), valid)


def expect_sample(payload: bytes) -> str:
    """What FuzzTarget.on_tick does with `payload`: undecodable, rejected_* (runtime.core.guard:
    not a Tick, or fields that do not fit it), error or ok."""
    try:
        msg = decode(payload).msg
    except Exception:
        return "undecodable"
    try:
        Admission(Tick)(msg)
    except Rejected as exc:
        return exc.reason.counter
    try:
        msg.n - msg.n + 1  # the handler's body
        return "ok"
    except Exception:
        return "error"


def expect_call(payload: bytes) -> tuple[str, Any]:
    """What FuzzTarget.add answers to `payload`: (undecodable|rejected_*|error|ok, total)."""
    try:
        req = decode(payload).msg
    except Exception:
        return "undecodable", None
    try:
        check_message(req)
    except Rejected as exc:
        return exc.reason.counter, None
    try:
        total = req.a + req.b
        encode(AddReply(total))
        return "ok", total
    except Exception:
        return "error", None


# ------------------------------------------------------------------ the node under fire

@dataclass
class Target:
    """The node process, the raw client session, and what the node should have counted."""

    proc: subprocess.Popen[bytes]
    log: Path
    session: Any
    publisher: Any
    expected: Counter[str] = field(default_factory=Counter)

    def stats(self) -> dict[str, int]:
        for reply in self.session.get(node_key(FLEET, KeyKind.STATS, "target"), timeout=2.0):
            if reply.ok is not None:
                return msgpack.unpackb(reply.ok.payload.to_bytes())
        raise AssertionError(f"no statistics from the node:\n{self.output()}")

    def output(self) -> str:
        return self.log.read_text(errors="replace")

    def wait_handled(self, count: int, timeout: float = 10.0) -> dict[str, int]:
        """Statistics once `count` samples and requests arrived and none waits in the inbox."""
        deadline = time.monotonic() + timeout
        while True:
            stats = self.stats()
            done = stats["received"] >= count and stats["inbox_depth"] == 0
            if done or time.monotonic() > deadline:
                return stats
            time.sleep(0.02)


@pytest.fixture(scope="module")
def target(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Target]:
    tmp = tmp_path_factory.mktemp("fuzz")
    scenario = tmp / "fuzz.yaml"
    scenario.write_text(SCENARIO)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = zenoh.open(zenoh_config(listen=[endpoint], mode="router"))
    session = zenoh.open(zenoh_config(connect=[endpoint]))
    log = tmp / "target.log"
    with log.open("w") as sink:
        proc = subprocess.Popen([sys.executable, "-m", "twinfleet.runtime.fleet.node_main", "--scenario",
                                 str(scenario), "--node", "target", "--connect", endpoint],
                                stdout=sink, stderr=subprocess.STDOUT, cwd=ROOT)
    publisher = session.declare_publisher(TICKS, congestion_control=zenoh.CongestionControl.BLOCK)
    try:
        deadline = time.monotonic() + 20
        while not publisher.matching_status.matching:
            assert time.monotonic() < deadline and proc.poll() is None, log.read_text()
            time.sleep(0.02)
        yield Target(proc, log, session, publisher)
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=5)
        publisher.undeclare()
        session.close()
        router.close()


@settings(max_examples=150, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(samples=st.lists(payloads, min_size=1, max_size=25),
       requests=st.lists(payloads, max_size=3))
def test_garbage_is_counted_and_the_node_keeps_serving(target: Target, samples: list[bytes],
                                                       requests: list[bytes]) -> None:
    for payload in samples:
        target.expected["received"] += 1
        target.expected[f"sample_{expect_sample(payload)}"] += 1
        target.publisher.put(payload)
    for payload in requests:
        outcome, total = expect_call(payload)
        target.expected["received"] += 1
        target.expected[f"call_{outcome}"] += 1
        started = time.monotonic()
        replies = list(target.session.get(ADD, payload=payload, timeout=CALL_TIMEOUT_S))
        assert time.monotonic() - started < CALL_TIMEOUT_S / 2, "the node did not finalise"
        assert len(replies) == 1, replies
        reply = replies[0]
        if outcome == "ok":
            assert reply.ok is not None, reply.err.payload.to_string()
            assert decode(reply.ok.payload.to_bytes()).msg == AddReply(total)
        else:
            assert reply.err is not None
            assert reply.err.payload.to_string().startswith("server error"), \
                reply.err.payload.to_string()
    stats = target.wait_handled(target.expected["received"])
    e = target.expected
    assert stats["received"] == e["received"], (stats, e, target.output()[-2000:])
    assert stats["dropped_undecodable"] == e["sample_undecodable"] + e["call_undecodable"]
    assert stats["handler_errors"] == e["sample_error"] + e["call_error"]
    for counter in ("rejected_invalid", "rejected_wrong_type"):
        assert stats[counter] == e[f"sample_{counter}"] + e[f"call_{counter}"], (counter, stats, e)
    assert target.proc.poll() is None, target.output()[-2000:]


def test_after_the_fuzzing_the_node_still_answers_and_stops_cleanly(target: Target) -> None:
    replies = list(target.session.get(ADD, payload=encode(AddRequest(2, 40)), timeout=5))
    assert [decode(r.ok.payload.to_bytes()).msg for r in replies] == [AddReply(42)]
    stats = target.stats()
    print("\nfuzz figures:", json.dumps({**target.expected, "node_stats": stats}))
    assert target.expected["received"] > 0
    target.proc.send_signal(signal.SIGINT)
    assert target.proc.wait(timeout=10) == 0, target.output()[-2000:]
    out = target.output()
    assert "Exception in callback" not in out and "exception was never retrieved" not in out
    assert out.count("Traceback") <= out.count("error in handler")  # only handlers' own errors
