"""Logic of the data-plane monitoring commands: `topic echo|hz|pub` and `service call`.

Like `runtime.tools.monitor.graph_verbs` (the graph verbs), each command takes a `Connection`
and returns an exit code, and a fleet or topic that is not there is reported
after the discovery timeout instead of being waited on silently. `echo` uses
an advanced subscriber with history, so a latched topic (``/map``) prints its
last sample however late the echo starts. `pub` and `call` check the message
against its type first (`runtime.tools.monitor.payload`) and `pub` warns when no subscriber
matches. Before either sends, `refuse_other_type` compares the type with what the fleet's
nodes say the name carries (``@info``: the types their subscriptions admit and their
services take, the type of what they published) and refuses a mismatch, naming both types:
a node would refuse the message, and a live verdict would count it as lost input.
"""

from __future__ import annotations

import sys
import time
from collections import deque
from collections.abc import Sequence
from typing import Any, TextIO, final

import msgpack
import yaml
import zenoh

from twinfleet.runtime.access.connection import CommandError, Connection
from twinfleet.runtime.contract.messages import registered_types
from twinfleet.runtime.core.guard import signer
from twinfleet.runtime.host.keys import topic_expr
from twinfleet.runtime.tools.monitor import graph as g
from twinfleet.runtime.tools.monitor.graph_verbs import (
    POLL_S,
    checked_type,
    graph_of,
    inline,
    known_topic,
    open_session,
    pick,
)
from twinfleet.runtime.tools.monitor.payload import PayloadError, build_fields, envelope


def render_envelope(payload: bytes, *, full: bool = False) -> str:
    """A YAML rendering of a raw sample (no message classes needed): the message's fields,
    as ``ros2 topic echo`` prints them, or with `full` the whole envelope (type, stamp_ms,
    seq, sender, data)."""
    try:
        env = msgpack.unpackb(payload, raw=False, strict_map_key=False)
    except Exception as exc:  # msgpack raises several unrelated types
        return f"<undecodable payload of {len(payload)} bytes: {exc}>\n"
    shown = env if full or not isinstance(env, dict) else env.get("data", {})
    if not isinstance(shown, dict):
        return yaml.safe_dump(shown, default_flow_style=None, width=100)
    # one line per top-level field as ros2 prints it, nested values inline
    return "".join(yaml.safe_dump({k: v}, sort_keys=False, width=100, default_flow_style=(
        None if isinstance(v, dict | list) else False)) for k, v in shown.items())


def field_of(payload: bytes, path: str, *, full: bool = False) -> Any:
    """The value at dotted `path` of a sample's message (``cell``, ``cell.0``,
    ``header.stamp``), or with `full` of its envelope (``stamp_ms``, ``data.cell``);
    raises KeyError naming the missing part."""
    value: Any = msgpack.unpackb(payload, raw=False, strict_map_key=False)
    if not full:
        value = value["data"]
    for part in path.split("."):
        if isinstance(value, list | tuple) and part.lstrip("-").isdigit():
            value = value[int(part)]
        elif isinstance(value, dict) and part in value:
            value = value[part]
        else:
            raise KeyError(part)
    return value


@final
class EchoTally:
    """What an echo printed and what it could not decode. An undecodable sample is one line
    on `err`, the first of each reason only (a stream of them would drown the output); it
    counts as a sample for ``--once``/``--count``, and the echo then ends with exit 1."""

    def __init__(self, topic: str, err: TextIO) -> None:
        self.topic, self.err = topic, err
        self.shown = 0
        self.bad: dict[str, int] = {}  # reason -> samples

    @property
    def seen(self) -> int:
        """Samples taken, decodable or not."""
        return self.shown + sum(self.bad.values())

    def undecodable(self, reason: str) -> None:
        """Count one sample that could not be decoded (say the first of its reason)."""
        if reason not in self.bad:
            print(f"{self.topic}: a sample is not decodable here ({reason})", file=self.err,
                  flush=True)
        self.bad[reason] = self.bad.get(reason, 0) + 1

    def exit_code(self) -> int:
        """0, or 1 when some sample was not decodable (the total said, if more than one)."""
        total = sum(self.bad.values())
        if total > 1:
            print(f"{self.topic}: {total} samples were not decodable here", file=self.err,
                  flush=True)
        return 1 if total else 0


def topic_echo(conn: Connection, topic: str, *, out: TextIO, count: int | None = None,
               duration_s: float | None = None, field: str | None = None, wait: bool = False,
               timeout_s: float = 1.0, err: TextIO = sys.stderr, full: bool = False) -> int:
    """Print each sample's message on `topic` as YAML, `---` between samples (`field`: that
    field only, bare; `full`: the whole envelope).

    A latched topic's last sample arrives at once, however late the echo starts.
    Returns 0, 1 when a sample was not decodable (`EchoTally`), or 2 when the topic is
    unknown (no publisher, no subscriber; with `wait`, a warning and a wait instead) or
    `count` samples did not arrive in time.
    """
    tally = EchoTally(topic, err)
    deadline = None if duration_s is None else time.monotonic() + duration_s
    with open_session(conn) as session:
        graph = graph_of(session, conn, timeout_s, warn=err if wait else None)
        where = pick(conn, graph, topic, "topic")
        latched = g.latched_topics(g.node_infos(session, where[0], timeout_s))
        samples: deque[bytes] = deque()
        sub = g.subscribe(session, topic_expr(*where), lambda s: samples.append(
            s.payload.to_bytes()), history=True)
        try:
            _check_echo_topic(conn, graph, where, latched, wait, timeout_s, err, samples)
            while (count is None or tally.seen < count) and (
                    deadline is None or time.monotonic() < deadline):
                while samples and (count is None or tally.seen < count):
                    _print_sample(out, samples.popleft(), field, where[1], full, tally)
                out.flush()
                time.sleep(POLL_S)
        except KeyboardInterrupt:
            pass
        finally:
            sub.undeclare()
    if count is not None and tally.seen < count:
        raise CommandError(f"{where[1]}: {tally.seen} of {count} messages within "
                           f"{duration_s:g} s")
    return tally.exit_code()


def _check_echo_topic(conn: Connection, graph: g.Graph, where: tuple[str, str],
                      latched: set[tuple[str, str]], wait: bool, timeout_s: float, err: TextIO,
                      samples: deque[bytes]) -> None:
    if where in graph.publishers or where in graph.subscribers or where in latched:
        return
    deadline = time.monotonic() + timeout_s
    while not samples and time.monotonic() < deadline:
        time.sleep(POLL_S)
    if samples:
        return
    topics = ", ".join(t for f, t in graph.topics() if f == where[0])
    text = (f"no node publishes or subscribes {where[1]} in fleet {where[0]!r} "
            f"(topics: {topics})")
    if not wait:
        raise CommandError(text + "; add --wait to wait for a publisher")
    print(f"warning: {text}; waiting for a publisher", file=err, flush=True)


def _print_sample(out: TextIO, payload: bytes, field: str | None, topic: str,
                  full: bool, tally: EchoTally) -> None:
    try:
        msgpack.unpackb(payload, raw=False, strict_map_key=False)
    except Exception as exc:  # msgpack raises several unrelated types
        tally.undecodable(f"not a twinfleet envelope: {exc}")
        return
    tally.shown += 1
    if field is None:
        out.write(render_envelope(payload, full=full) + "---\n")
        return
    try:
        value = field_of(payload, field, full=full)
    except (KeyError, IndexError, ValueError, TypeError) as exc:
        raise CommandError(f"{topic}: its messages have no field {field!r} "
                           f"(missing {exc}); fields: {_fields(payload)}") from None
    out.write(yaml.safe_dump(value, default_flow_style=None, width=100, sort_keys=False)
              .removesuffix("...\n") + "---\n")


def _fields(payload: bytes) -> str:
    try:
        data = msgpack.unpackb(payload, raw=False, strict_map_key=False).get("data", {})
    except Exception:  # msgpack raises several unrelated types
        return "?"
    return ", ".join(map(str, data)) if isinstance(data, dict) else "?"


def rate_report(stamps: Sequence[float]) -> str | None:
    """`ros2 topic hz`-style line for arrival times `stamps` (seconds), or None if < 2."""
    if len(stamps) < 2:
        return None
    gaps = [b - a for a, b in zip(stamps, stamps[1:], strict=False)]
    mean = sum(gaps) / len(gaps)
    std = (sum((x - mean) ** 2 for x in gaps) / len(gaps)) ** 0.5
    rate = 1.0 / mean if mean > 0 else float("inf")
    return (f"average rate: {rate:.3f} Hz  min: {min(gaps):.4f} s  max: {max(gaps):.4f} s  "
            f"std dev: {std:.5f} s  window: {len(stamps)}")


def topic_hz(conn: Connection, topic: str, *, out: TextIO, window: int = 100,
             duration_s: float | None = None, every_s: float = 1.0,
             timeout_s: float = 1.0, wait: bool = False, err: TextIO = sys.stderr) -> int:
    """Print the publishing rate of `topic` every `every_s` over the last `window` samples
    (`wait`: a topic no node uses yet is a warning, and the rate follows once it is used)."""
    stamps: deque[float] = deque(maxlen=max(2, window))
    deadline = None if duration_s is None else time.monotonic() + duration_s
    arrivals: deque[float] = deque()
    with open_session(conn) as session:
        graph = graph_of(session, conn, timeout_s, warn=err if wait else None)
        where = pick(conn, graph, topic, "topic")
        try:
            known_topic(conn, graph, where)
        except CommandError as exc:
            if not wait:
                raise
            print(f"warning: {exc}; waiting for a publisher", file=err, flush=True)
        sub = session.declare_subscriber(topic_expr(*where),
                                         lambda _s: arrivals.append(time.monotonic()))
        next_report = time.monotonic() + every_s
        try:
            while deadline is None or time.monotonic() < deadline:
                time.sleep(POLL_S)
                while arrivals:
                    stamps.append(arrivals.popleft())
                if time.monotonic() >= next_report:
                    next_report += every_s
                    print(rate_report(list(stamps)) or "no new messages", file=out, flush=True)
        except KeyboardInterrupt:
            pass
        finally:
            sub.undeclare()
    if not stamps:
        raise CommandError(f"{where[1]}: no message within {duration_s:g} s")
    return 0


def _known_schemas(session: zenoh.Session, fleet: str, timeout_s: float) -> dict[str, Any]:
    return {name: schema for name, (schema, _) in g.served_schemas(session, fleet,
                                                                     timeout_s).items()}


def _payload_fields(type_name: str, data: Any, known: dict[str, Any]) -> dict[str, Any]:
    try:
        return build_fields(type_name, data, known)
    except PayloadError as exc:
        raise CommandError(str(exc)) from None


def topic_pub(conn: Connection, topic: str, type_name: str, data: dict[str, Any], *,
              out: TextIO, rate_hz: float = 1.0, count: int | None = 1,
              wait_matched_s: float = 2.0, timeout_s: float = 1.0,
              err: TextIO = sys.stderr) -> int:
    """Publish `data` as `type_name` on `topic` `count` times (None: until Ctrl-C) at `rate_hz`.

    The message is checked against the type first (`runtime.tools.monitor.payload`); a warning
    says when no subscriber matches within `wait_matched_s`.
    """
    sent = 0
    type_name = checked_type(type_name)
    with open_session(conn, write=True) as session:
        fields = _payload_fields(type_name, data, _known_schemas(session, conn.fleet, timeout_s))
        key = topic_expr(conn.fleet, topic)
        tag = signer(conn.auth.key, key)  # the fleet's nodes take only signed samples
        pub = session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
        deadline = time.monotonic() + wait_matched_s
        while not _matched(pub) and time.monotonic() < deadline:
            time.sleep(POLL_S)
        if not _matched(pub):
            print(f"warning: no subscriber on {topic} in fleet {conn.fleet!r} (waited "
                  f"{wait_matched_s:g} s); publishing anyway", file=err, flush=True)
        try:
            while count is None or sent < count:
                payload = envelope(type_name, fields, seq=sent + 1)
                pub.put(payload, attachment=tag(payload))
                sent += 1
                print(f"published #{sent} on {topic}: {type_name} {inline(fields)}",
                      file=out, flush=True)
                if count is None or sent < count:
                    time.sleep(1.0 / rate_hz)
        except KeyboardInterrupt:
            pass
        finally:
            pub.undeclare()
    return 0


def service_call(conn: Connection, service: str, type_name: str, data: dict[str, Any], *,
                 out: TextIO, timeout_s: float = 2.0, discovery_s: float = 1.0,
                 full: bool = False) -> int:
    """Call `service` once and print the reply's fields (`full`: its envelope); 2 on error,
    timeout or no server."""
    type_name = checked_type(type_name, service=True)
    with open_session(conn, write=True) as session:
        fields = _payload_fields(type_name, data, _known_schemas(session, conn.fleet,
                                                                 discovery_s))
        key, payload = topic_expr(conn.fleet, service), envelope(type_name, fields)
        replies = list(session.get(key, payload=payload, timeout=timeout_s,
                                   attachment=signer(conn.auth.key, key)(payload)))
    for reply in replies:
        if reply.ok is not None:
            out.write(render_envelope(reply.ok.payload.to_bytes(), full=full))
            out.flush()
            return 0
        if reply.err is not None:
            text = reply.err.payload.to_string()
            raise CommandError(f"{service}: " + (f"no reply within {timeout_s:g} s"
                                                 if text == "Timeout" else text))
    raise CommandError(f"{service}: no server in fleet {conn.fleet!r} "
                       "(see `twinfleet service list`)")


def carried_types(infos: dict[tuple[str, str], dict[str, Any]], name: str, *,
                  service: bool = False) -> dict[str, list[str]]:
    """type → the nodes that say `name` carries it (``@info``; "?" left out): the types
    their subscriptions admit and they published, or the request type a service takes."""
    said: dict[str, list[str]] = {}
    for (_, node), info in sorted(infos.items()):
        if service:
            kinds = [(info.get("service_types") or {}).get(name, ["?"])[0]]
        else:
            kinds = [(info.get(table) or {}).get(name, "?")
                     for table in ("subscription_types", "publications")]
        for kind in dict.fromkeys(kinds):
            if isinstance(kind, str) and kind != "?":
                said.setdefault(kind, []).append(node)
    return said


def refuse_other_type(conn: Connection, name: str, type_name: str, *, service: bool = False,
                      force: bool = False, timeout_s: float = 1.0, err: TextIO = sys.stderr
                      ) -> None:
    """Raise `CommandError` naming both types when the fleet's nodes say `name` carries a type
    other than `type_name`; with `force`, warn and return (the caller sends anyway)."""
    wanted = checked_type(type_name, service=service)
    with open_session(conn) as session:
        said = carried_types(g.node_infos(session, conn.fleet, timeout_s), name, service=service)
        other = {kind: nodes for kind, nodes in said.items() if kind != wanted}
        if not other or (wanted not in registered_types() and wanted not in
                         _known_schemas(session, conn.fleet, timeout_s)):
            return  # a type no one knows: the message check says so, more precisely
    text = "; ".join(f"{kind} ({', '.join(nodes)})" for kind, nodes in other.items())
    what = "takes" if service else "carries"
    if not force:
        raise CommandError(f"{name} {what} {text}, not {wanted}; give --force to send "
                           f"{wanted} anyway")
    print(f"warning: {name} {what} {text}, not {wanted}; sending it anyway (--force): the "
          "nodes will refuse it", file=err, flush=True)


def _matched(pub: Any) -> bool:
    """Whether a subscriber matches `pub` (zenoh's stubs type `matching_status` as a bool; it
    is a `MatchingStatus`)."""
    return bool(pub.matching_status.matching)
