"""Logic of the monitoring commands: `topic list|echo|hz|pub`, `service list|call`, `node list`.

Each command is a plain function taking a Zenoh config and the fleet name and
returning an exit code; `runtime.cli` only parses arguments. The monitors read
the wire format directly (msgpack envelopes, liveliness graph keys, see
`runtime.transport`), so they work on any fleet without importing its node
code. Subscriber callbacks only append to a deque (no wake-up per sample);
the main thread polls it.

`fleet` may be ``*`` for read-only commands (every fleet on the router).
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Sequence
from typing import Any, TextIO

import msgpack
import yaml
import zenoh

from twinfleet.runtime.messages import (
    DecodeError,
    from_plain,
    message_class,
    to_plain,
    type_name_of,
)
from twinfleet.runtime.names import KEY_PREFIX
from twinfleet.runtime.transport import graph_key, parse_graph_key

_POLL_S = 0.02
CLI_SENDER = "twinfleet-cli"


def data_key(fleet: str, name: str) -> str:
    """Key expression of topic or service `name` (fully qualified) in `fleet` (may be `*`)."""
    if not name.startswith("/"):
        name = "/" + name
    return f"{KEY_PREFIX}/{fleet}{name}"


def _liveliness(session: zenoh.Session, key_expr: str, timeout_s: float) -> list[str]:
    keys = []
    for reply in session.liveliness().get(key_expr, timeout=timeout_s):
        if reply.ok is not None:
            keys.append(str(reply.ok.key_expr))
    return sorted(set(keys))


def _graph(session: zenoh.Session, fleet: str, kind: str, timeout_s: float
           ) -> list[tuple[str, str, str, str]]:
    pattern = graph_key(fleet, kind, "*") + ("/**" if kind != "node" else "")
    return [parse_graph_key(k) for k in _liveliness(session, pattern, timeout_s)]


def node_list(conf: zenoh.Config, fleet: str, *, out: TextIO, stats: bool = False,
              timeout_s: float = 1.0) -> int:
    """Print the running nodes (one liveliness token each); with `stats`, their counters."""
    with zenoh.open(conf) as session:
        nodes = _graph(session, fleet, "node", timeout_s)
        counters = _stats(session, fleet, timeout_s) if stats else {}
    for node_fleet, _, name, _ in nodes:
        line = f"{name}" if fleet != "*" else f"{node_fleet}/{name}"
        extra = counters.get((node_fleet, name))
        if extra:
            line += "  " + " ".join(f"{k}={v}" for k, v in extra.items())
        print(line, file=out, flush=True)
    return 0


def _stats(session: zenoh.Session, fleet: str, timeout_s: float) -> dict[tuple[str, str], Any]:
    result = {}
    for reply in session.get(f"{KEY_PREFIX}/{fleet}/@stats/*", timeout=timeout_s):
        if reply.ok is not None:
            parts = str(reply.ok.key_expr).split("/")
            result[(parts[1], parts[3])] = msgpack.unpackb(reply.ok.payload.to_bytes())
    return result


def topic_list(conf: zenoh.Config, fleet: str, *, out: TextIO, verbose: bool = False,
               timeout_s: float = 1.0) -> int:
    """Print the topics that running nodes publish or subscribe to."""
    with zenoh.open(conf) as session:
        pubs = _graph(session, fleet, "pub", timeout_s)
        subs = _graph(session, fleet, "sub", timeout_s)
    _print_graph(out, fleet, {"publishers": pubs, "subscribers": subs}, verbose)
    return 0


def service_list(conf: zenoh.Config, fleet: str, *, out: TextIO, verbose: bool = False,
                 timeout_s: float = 1.0) -> int:
    """Print the services that running nodes serve."""
    with zenoh.open(conf) as session:
        srvs = _graph(session, fleet, "srv", timeout_s)
    _print_graph(out, fleet, {"servers": srvs}, verbose)
    return 0


def _print_graph(out: TextIO, fleet: str, groups: dict[str, list[tuple[str, str, str, str]]],
                 verbose: bool) -> None:
    names: dict[str, dict[str, list[str]]] = {}
    for label, entries in groups.items():
        for entry_fleet, _, node, name in entries:
            shown = name if fleet != "*" else f"{entry_fleet}:{name}"
            names.setdefault(shown, {}).setdefault(label, []).append(node)
    for name in sorted(names):
        if not verbose:
            print(name, file=out)
            continue
        roles = "; ".join(f"{label}: {', '.join(sorted(nodes))}"
                          for label, nodes in sorted(names[name].items()))
        print(f"{name}  [{roles}]", file=out)
    out.flush()


def render_envelope(payload: bytes) -> str:
    """A YAML rendering of a raw envelope (no message classes needed)."""
    try:
        env = msgpack.unpackb(payload, raw=False, strict_map_key=False)
    except Exception as exc:  # msgpack raises several unrelated types
        return f"<undecodable payload of {len(payload)} bytes: {exc}>\n"
    return yaml.safe_dump(env, sort_keys=False, default_flow_style=None, width=100)


def _collect(session: zenoh.Session, key: str) -> tuple[Any, deque[tuple[float, bytes]]]:
    samples: deque[tuple[float, bytes]] = deque()

    def on_sample(sample: zenoh.Sample) -> None:
        samples.append((time.monotonic(), sample.payload.to_bytes()))

    return session.declare_subscriber(key, on_sample), samples


def topic_echo(conf: zenoh.Config, fleet: str, topic: str, *, out: TextIO,
               count: int | None = None, duration_s: float | None = None) -> int:
    """Print each sample on `topic` as YAML, `---` between samples.

    Returns 0, or 1 when `count` samples did not arrive within `duration_s`.
    """
    seen = 0
    deadline = None if duration_s is None else time.monotonic() + duration_s
    with zenoh.open(conf) as session:
        sub, samples = _collect(session, data_key(fleet, topic))
        try:
            while (count is None or seen < count) and (deadline is None or time.monotonic() < deadline):
                while samples and (count is None or seen < count):
                    _, payload = samples.popleft()
                    out.write(render_envelope(payload) + "---\n")
                    seen += 1
                out.flush()
                time.sleep(_POLL_S)
        except KeyboardInterrupt:
            pass
        finally:
            sub.undeclare()
    return 0 if count is None or seen >= count else 1


def rate_report(stamps: Sequence[float]) -> str | None:
    """`ros2 topic hz`-style line for arrival times `stamps` (seconds), or None if < 2."""
    if len(stamps) < 2:
        return None
    gaps = [b - a for a, b in zip(stamps, stamps[1:], strict=False)]
    mean = sum(gaps) / len(gaps)
    std = (sum((g - mean) ** 2 for g in gaps) / len(gaps)) ** 0.5
    rate = 1.0 / mean if mean > 0 else float("inf")
    return (f"average rate: {rate:.3f} Hz  min: {min(gaps):.4f} s  max: {max(gaps):.4f} s  "
            f"std dev: {std:.5f} s  window: {len(stamps)}")


def topic_hz(conf: zenoh.Config, fleet: str, topic: str, *, out: TextIO, window: int = 100,
             duration_s: float | None = None, every_s: float = 1.0) -> int:
    """Print the publishing rate of `topic` every `every_s` over the last `window` samples."""
    stamps: deque[float] = deque(maxlen=max(2, window))
    deadline = None if duration_s is None else time.monotonic() + duration_s
    got_any = False
    with zenoh.open(conf) as session:
        sub, samples = _collect(session, data_key(fleet, topic))
        next_report = time.monotonic() + every_s
        try:
            while deadline is None or time.monotonic() < deadline:
                time.sleep(_POLL_S)
                while samples:
                    stamps.append(samples.popleft()[0])
                    got_any = True
                if time.monotonic() >= next_report:
                    next_report += every_s
                    print(rate_report(list(stamps)) or "no new messages", file=out, flush=True)
        except KeyboardInterrupt:
            pass
        finally:
            sub.undeclare()
    return 0 if got_any else 1


def build_payload(type_name: str, data: Any, *, seq: int = 0, stamp_ms: int = 0) -> bytes:
    """An envelope for `data` (a mapping from YAML); validated when the type is registered."""
    fields = data if isinstance(data, dict) else {}
    if data is not None and not isinstance(data, dict):
        raise ValueError(f"message data must be a mapping of fields, got {data!r}")
    try:
        cls = message_class(type_name)
    except DecodeError:
        plain = fields  # unknown here: send as given, receivers validate
    else:
        msg = from_plain({**fields, "_type": type_name})
        if type(msg) is not cls:
            raise ValueError(f"could not build {type_name} from {data!r}")
        plain = to_plain(msg)
        plain.pop("_type")
        type_name = type_name_of(msg)
    envelope = {"type": type_name, "stamp_ms": stamp_ms, "seq": seq, "sender": CLI_SENDER,
                "data": plain}
    return msgpack.packb(envelope, use_bin_type=True)


def topic_pub(conf: zenoh.Config, fleet: str, topic: str, type_name: str, data: Any, *,
              out: TextIO, rate_hz: float = 1.0, count: int | None = 1,
              wait_matched_s: float = 2.0) -> int:
    """Publish `data` as `type_name` on `topic` `count` times (None: until Ctrl-C) at `rate_hz`."""
    sent = 0
    with zenoh.open(conf) as session:
        pub = session.declare_publisher(data_key(fleet, topic),
                                        congestion_control=zenoh.CongestionControl.BLOCK)
        deadline = time.monotonic() + wait_matched_s
        while not pub.matching_status and time.monotonic() < deadline:
            time.sleep(_POLL_S)
        if not pub.matching_status:
            print(f"warning: no subscriber matches {topic} yet", file=out, flush=True)
        try:
            while count is None or sent < count:
                pub.put(build_payload(type_name, data, seq=sent + 1))
                sent += 1
                print(f"published #{sent} on {topic}", file=out, flush=True)
                if count is None or sent < count:
                    time.sleep(1.0 / rate_hz)
        except KeyboardInterrupt:
            pass
        finally:
            pub.undeclare()
    return 0


def service_call(conf: zenoh.Config, fleet: str, service: str, type_name: str, data: Any, *,
                 out: TextIO, timeout_s: float = 2.0) -> int:
    """Call `service` once and print the reply envelope; 1 on error, timeout or no server."""
    payload = build_payload(type_name, data)
    with zenoh.open(conf) as session:
        replies = list(session.get(data_key(fleet, service), payload=payload, timeout=timeout_s))
    for reply in replies:
        if reply.ok is not None:
            out.write(render_envelope(reply.ok.payload.to_bytes()))
            out.flush()
            return 0
        if reply.err is not None:
            text = reply.err.payload.to_string()
            print(f"error: {service}: {'timeout' if text == 'Timeout' else text}", file=out, flush=True)
            return 1
    print(f"error: {service}: no server", file=out, flush=True)
    return 1


def parse_data(text: str | None) -> Any:
    """YAML text of message fields (`"{a: 1, b: 2}"`) → mapping; empty → {}."""
    if not text:
        return {}
    return yaml.safe_load(text)

