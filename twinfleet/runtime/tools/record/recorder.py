"""`twinfleet record` and `twinfleet play`: fleet topics to an MCAP file and back onto Zenoh.

File layout (MCAP, written with the `mcap` package, zstd chunks, full index):

* one **schema** per message type: name = the envelope's type name (e.g.
  ``std_msgs/String``), encoding ``jsonschema``, data = a JSON Schema
  of the envelope ``{type, stamp_ms, seq, sender, data}`` whose ``data`` lists
  the dataclass fields of the registered message class (`runtime.host.schemas`;
  joining a running fleet, the schemas its node processes serve; inferred
  from the first sample, and said so, when neither knows the type);
* one **channel** per topic key (and type): topic = the fully qualified name
  (``/r1/scan``), message encoding ``msgpack``, metadata ``key`` (the Zenoh
  key), ``fleet`` and ``durability`` (``transient_local`` for the topics the
  fleet's nodes declare so: `runtime.host.introspect.latched_topics`);
* **messages**: the raw envelope bytes as received; log time = receive time
  (ns since the Unix epoch, made strictly increasing so that log-time order
  is arrival order), publish time = log time, sequence = arrival index.
* one metadata record ``twinfleet`` (fleet, scenario, time scale, seed, and
  ``scene``, the import name of the fleet's scene when it names one: how
  `twinfleet export` draws the recording, and what `play` tells viewers).

Crash safety. Messages are written in chunks as they come: the chunk in
progress is closed and flushed to the file at least every `FLUSH_S` seconds
(and whenever it reaches `CHUNK_BYTES`), so after a kill -9 the file holds
every chunk up to the last flush; it then has no summary, and `twinfleet bag
repair FILE` (`runtime.tools.record.bag.repair`) rewrites it as a complete recording. A
write that fails (a full disk: ENOSPC) stops the recording at once: the file
is cut back to its last complete chunk (readable after `bag repair`), and
`failed` holds the one line that says so.

`record_scenario` makes the recorder's session the fleet's router and then
launches the fleet with `run_fleet` (`LaunchOptions.connect`), so the recorder is subscribed
before the first node starts. `record_live` joins a running fleet and asks its
nodes for their message schemas (`fleet_schemas`) and the fleet for its
description (scene, latched topics: `runtime.host.keys.fleet_key`).
`play` re-publishes the messages in log-time order at the recorded pace
divided by `rate`, latched topics through advanced publishers, describes
each fleet it plays as its launcher did (from the recording), so that viewers
draw it, and is a node ``play`` of that fleet (liveliness and ``@info``), so that
every monitor finds the fleet as it finds a launched one.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import sys
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, BinaryIO, TextIO, final

import msgpack
from mcap.reader import make_reader
from mcap.writer import Writer

from twinfleet.runtime.contract.node import Durability
from twinfleet.runtime.core.guard import Role, signer
from twinfleet.runtime.host.introspect import latched_topics
from twinfleet.runtime.host.keys import (
    ANY,
    KeyKind,
    fleet_key,
    node_key,
    topic_expr,
    topic_in_fleet,
)
from twinfleet.runtime.host.schemas import message_schema
from twinfleet.runtime.host.zenoh_transport import zenoh_config
from twinfleet.runtime.tools.monitor.graph import fleet_infos, fleet_schemas
from twinfleet.runtime.tools.monitor.tap import FleetTap, follow_relaunches, tap_config

DRAIN_S = 0.3
LINGER_S = 0.5
FLUSH_S = 0.5  # the chunk in progress reaches the file at least this often (wall seconds)
CHUNK_BYTES = 256 * 1024
PLAYER = "play"  # the node name `play` has in the fleets it plays (`_announce`)
@final
class McapRecorder:
    """Writes raw envelopes to an MCAP file: a schema per type, a channel per topic key.

    Args:
        stream: a binary file opened for writing (closed by `close`).
        latched: fully qualified names recorded with durability ``transient_local``.
    """

    def __init__(self, stream: BinaryIO, *, latched: tuple[str, ...] = (),
                 on_failure: Callable[[str], None] | None = None) -> None:
        self.known_schemas: dict[str, dict[str, Any]] = {}  # data schemas the fleet served
        self._stream = stream
        self.failed: str | None = None  # why the recording stopped early (module docstring)
        self.on_failure = on_failure
        self._good = 0  # file offset after the last complete flush
        self._flushed_at = time.monotonic()
        self._writer = Writer(stream, chunk_size=CHUNK_BYTES)
        self._guarded(lambda: self._writer.start(profile="", library="twinfleet"))
        self.latched = latched
        self._schemas: dict[str, int] = {}
        self._channels: dict[tuple[str, str], int] = {}
        self._last_ns = 0
        self.messages = 0
        self.undecodable = 0

    def metadata(self, values: Mapping[str, Any]) -> None:
        """Add the ``twinfleet`` metadata record (values become strings)."""
        self._guarded(lambda: self._writer.add_metadata(
            "twinfleet", {k: str(v) for k, v in values.items()}))
        self.flush()

    def flush(self) -> None:
        """Close the chunk in progress and write it to the file (now)."""
        if self._guarded(self._writer.flush):
            self._good = self._stream.tell()
        self._flushed_at = time.monotonic()

    def flush_due(self) -> None:
        """`flush` if the last one is `FLUSH_S` old (a periodic task calls this)."""
        if self.failed is None and time.monotonic() - self._flushed_at >= FLUSH_S:
            self.flush()

    def _guarded(self, write: Callable[[], Any]) -> bool:
        """Run a write; on OSError stop the recording (module docstring). False if it failed."""
        if self.failed is not None:
            return False
        try:
            write()
            return True
        except OSError as exc:
            name = getattr(self._stream, "name", "the recording")
            self.failed = (f"recording stopped after {self.messages} messages: cannot write "
                           f"{name} ({exc.strerror or exc}); the file keeps what was written "
                           f"before: `twinfleet bag repair {name}` makes it a complete recording")
            with contextlib.suppress(OSError, ValueError):
                self._stream.truncate(self._good)  # cut a half-written chunk off
            if self.on_failure is not None:
                self.on_failure(self.failed)
            return False

    def write(self, key: str, payload: bytes) -> None:
        """Record one sample of `key` received now."""
        where = topic_in_fleet(ANY, key)
        if self.failed is not None or where is None:
            return
        try:
            env = msgpack.unpackb(payload, raw=False, strict_map_key=False)
            type_name = env["type"] if isinstance(env, dict) and isinstance(env.get("type"), str) else None
        except Exception:  # msgpack raises several unrelated types
            env, type_name = None, None
        if type_name is None:
            self.undecodable += 1
            type_name = "twinfleet/Undecodable"
        now = max(time.time_ns(), self._last_ns + 1)
        self._last_ns = now

        def add() -> None:
            channel = self._channel(key, where.fleet, where.topic, type_name, env)
            self._writer.add_message(channel, log_time=now, data=payload, publish_time=now,
                                     sequence=self.messages)

        if self._guarded(add):
            self.messages += 1
        self.flush_due()

    def _channel(self, key: str, fleet: str, topic: str, type_name: str, env: Any) -> int:
        channel = self._channels.get((key, type_name))
        if channel is not None:
            return channel
        schema = self._schemas.get(type_name)
        if schema is None:
            sample = env.get("data") if isinstance(env, dict) else None
            text = json.dumps(message_schema(type_name, sample, self.known_schemas),
                              indent=1).encode()
            schema = self._writer.register_schema(type_name, "jsonschema", text)
            self._schemas[type_name] = schema
        durability = (Durability.TRANSIENT_LOCAL if topic in self.latched
                      else Durability.VOLATILE).value
        channel = self._writer.register_channel(topic, "msgpack", schema, {
            "key": key, "fleet": fleet, "durability": durability})
        self._channels[(key, type_name)] = channel
        return channel

    def close(self) -> None:
        """Write the summary and close the file (a failed recording stays as it was cut)."""
        if self.failed is None:
            self._guarded(self._writer.finish)
        with contextlib.suppress(OSError):
            self._stream.close()

    @property
    def topics(self) -> int:
        """Number of channels written so far."""
        return len(self._channels)


async def record_scenario(scenario: Any, path: str | Path, *, time_scale: float | None = None,
                          duration_s: float | None = None, seed: int | None = None,
                          listen: str | None = None, out: TextIO = sys.stdout) -> tuple[Any, McapRecorder]:
    """Launch `scenario` with the recorder as its router; record until the run ends.

    Returns the launcher's `FleetResult` and the (closed) recorder with its counts.
    """
    from twinfleet.runtime.fleet.launcher import LaunchOptions, free_port, run_fleet
    from twinfleet.runtime.fleet.live_fleet import with_free_port

    endpoint = with_free_port(listen) if listen else f"tcp/127.0.0.1:{free_port()}"
    failed = asyncio.Event()
    latched = tuple(latched_topics(scenario))
    recorder = McapRecorder(open(path, "wb"),  # noqa: SIM115 - closed by recorder.close()
                            latched=latched, on_failure=lambda _why: failed.set())
    recorder.metadata({"fleet": scenario.fleet, "scenario": scenario.path,
                       "seed": scenario.seed if seed is None else seed,
                       "time_scale": time_scale or scenario.live.time_scale,
                       **({"scene": scenario.scene} if scenario.scene else {})})
    tap = FleetTap(lambda: zenoh_config(listen=[endpoint], mode="router"), scenario.fleet,
                   recorder.write, latched=latched, retry=False)
    flusher: asyncio.Task[None] | None = None
    try:
        await tap.open()
        flusher = asyncio.create_task(_flush_until(recorder, failed))

        async def until_failed(_fleet: Any) -> str:
            await failed.wait()
            return str(recorder.failed)

        options = LaunchOptions(time_scale=time_scale, timeout_s=duration_s, seed=seed,
                                connect=endpoint)
        result = await run_fleet(scenario, options, out=out, driver=until_failed)
        await asyncio.sleep(DRAIN_S)  # the last samples may still be on their way
    finally:
        if flusher is not None:
            flusher.cancel()
        await tap.close()
        recorder.close()
    return result, recorder


async def _flush_until(recorder: McapRecorder, failed: asyncio.Event) -> None:
    """Flush the recorder every `FLUSH_S` / 2 (a quiet fleet sends nothing that would)."""
    while not failed.is_set():
        await asyncio.sleep(FLUSH_S / 2)
        recorder.flush_due()


async def record_live(connect: str, fleet: str, path: str | Path, *,
                      duration_s: float | None = None, stop: asyncio.Event | None = None,
                      handle_signals: bool = False, auth: Any = None) -> McapRecorder:
    """Record a running fleet reached at `connect` for `duration_s` or until `stop` is set
    (with `handle_signals`, also until SIGINT/SIGTERM); `auth`: the fleet's logins
    (`runtime.access.fleetauth.MonitorAuth`; default: this machine's registry, read again when
    the router goes away, so the recording follows a fleet launched again on `connect`)."""
    import signal

    stop = stop or asyncio.Event()
    if handle_signals:
        for sig in (signal.SIGINT, signal.SIGTERM):
            asyncio.get_running_loop().add_signal_handler(sig, stop.set)
    recorder = McapRecorder(open(path, "wb"),  # noqa: SIM115 - closed by recorder.close()
                            on_failure=lambda _why: stop.set())
    tap = FleetTap(lambda: tap_config(connect, auth), fleet, recorder.write,
                   retry=False)
    described: dict[str, Any] = {}

    def prepare(session: Any) -> None:
        """What must be known before the first sample is recorded: a sample recorded before
        its schema would get a guessed one, and one of a latched topic its durability."""
        recorder.known_schemas.update(fleet_schemas(session, fleet))
        described.update(_one_description(fleet_infos(session, fleet, 1.0)))
        recorder.latched = tap.latched = described["latched"]

    try:
        await tap.open(prepare=prepare)
        # written before the first sample: the tap delivers on the loop, after this returns
        scene = described.get("scene")
        recorder.metadata({"fleet": fleet, "connect": connect, **({"scene": scene} if scene else {})})
        waiter = asyncio.ensure_future(stop.wait())
        flusher = asyncio.create_task(_flush_until(recorder, stop))
        follower = asyncio.create_task(follow_relaunches(tap))
        await asyncio.wait([waiter], timeout=duration_s)
        for task in (waiter, flusher, follower):
            task.cancel()
        await asyncio.gather(follower, return_exceptions=True)
    finally:
        await tap.close()
        recorder.close()
    return recorder


def _one_description(infos: Mapping[str, Any]) -> dict[str, Any]:
    """What a recording of the fleets that answered `infos` says: every latched topic, and
    the scene they name if they name one between them (else None)."""
    scenes = {i.get("scene") for i in infos.values() if isinstance(i.get("scene"), str)}
    latched = sorted({t for i in infos.values() for t in i.get("latched") or ()
                      if isinstance(t, str)})
    return {"scene": scenes.pop() if len(scenes) == 1 else None, "latched": tuple(latched)}




def _describe_fleets(session: Any, reader: Any, summary: Any, fleet: str | None) -> list[Any]:
    """Serve, for each fleet a recording holds, the description its launcher served
    (`runtime.host.keys.fleet_key`): the recorded scene and the latched channels."""
    recorded = next((dict(m.metadata) for m in reader.iter_metadata() if m.name == "twinfleet"), {})
    latched: dict[str, set[str]] = {}
    for channel in (summary.channels.values() if summary else ()):
        name = fleet or channel.metadata.get("fleet")
        if name:
            topics = latched.setdefault(name, set())
            if channel.metadata.get("durability") == "transient_local":
                topics.add(channel.topic)
    queryables = []
    for name, topics in latched.items():
        payload = msgpack.packb({"scene": recorded.get("scene"), "latched": sorted(topics)},
                                use_bin_type=True)
        queryables.append(session.declare_queryable(fleet_key(name, "play"), _replier(name, payload)))
    return queryables


def _replier(fleet: str, payload: bytes, key: str | None = None) -> Callable[[Any], None]:
    def reply(query: Any) -> None:
        with query:  # finalised at once: the asker does not wait for its timeout
            query.reply(key or fleet_key(fleet, "play"), payload)
    return reply


def _announce(session: Any, summary: Any, fleet: str | None) -> list[Any]:
    """Make `play` a node of each fleet it plays, as the monitors find nodes: a ``@node``
    token for node `PLAYER`, a ``@pub`` token per topic it publishes, and ``@info`` naming
    each topic's recorded type, so that `topic list -t`, `topic echo` and `node list` see
    the played fleet as they see a launched one."""
    played: dict[str, dict[str, str]] = {}  # fleet -> topic -> type
    for channel in (summary.channels.values() if summary else ()):
        name = fleet or channel.metadata.get("fleet")
        schema = summary.schemas.get(channel.schema_id)
        if name:
            played.setdefault(name, {})[channel.topic] = schema.name if schema else "?"
    entities: list[Any] = []
    for name, topics in played.items():
        tokens = [node_key(name, KeyKind.NODE, PLAYER),
                  *(node_key(name, KeyKind.PUB, PLAYER, topic) for topic in sorted(topics))]
        entities += [session.liveliness().declare_token(key) for key in tokens]
        info = {"name": PLAYER, "namespace": "/", "class": "twinfleet play", "pid": os.getpid(),
                "params": {}, "subscriptions": {}, "subscription_types": {}, "services": [],
                "service_types": {}, "timers": [], "publication_qos": {},
                "publications": dict(sorted(topics.items()))}
        key = node_key(name, KeyKind.INFO, PLAYER)
        entities.append(session.declare_queryable(key, _replier(name, msgpack.packb(
            info, use_bin_type=True), key)))
    return entities


def play(make_config: Callable[[], Any], path: str | Path, *, rate: float = 1.0,
         fleet: str | None = None, out: TextIO = sys.stdout, wait_s: float = 2.0,
         linger_s: float = LINGER_S, key: bytes | None = None) -> int:
    """Publish every recorded message in log-time order, at the recorded pace divided by `rate`.

    Args:
        make_config: builds the Zenoh config (client of a router, or a router itself).
        path: the MCAP file.
        rate: speed factor (2 = twice as fast); must be > 0.
        fleet: publish into this fleet instead of the recorded one.
        out: where progress lines go.
        wait_s: wait up to this long for a subscriber to match before publishing.
        linger_s: keep the session open this long after the last message.
        key: sign every message with this fleet key as recorded input
            (`runtime.core.guard.Role.RECORDED`: ``play --into-fleet``); None: unsigned,
            which a fleet with a key drops.

    Returns 0, or 2 when the file holds no twinfleet messages.
    """
    import zenoh

    if not rate > 0:
        raise ValueError(f"rate must be > 0, got {rate}")
    with open(path, "rb") as stream, zenoh.open(make_config()) as session:
        reader = make_reader(stream)
        summary = reader.get_summary()
        pubs = _Publishers(session, path, fleet, key)
        for channel in (summary.channels.values() if summary else ()):
            pubs.declare(channel)
        described = _describe_fleets(session, reader, summary, fleet)
        described += _announce(session, summary, fleet)
        pubs.wait_for_subscriber(wait_s)
        started = time.monotonic()
        try:
            count = _publish_paced(reader, pubs, rate, started)
            time.sleep(linger_s)
        finally:
            pubs.undeclare()
            for entity in described:
                entity.undeclare()
    print(f"played {count} messages on {len(pubs)} topics in {time.monotonic() - started:.1f} s",
          file=out, flush=True)
    return 0 if count else 2


def _publish_paced(reader: Any, pubs: _Publishers, rate: float, started: float) -> int:
    """Publish the messages of `reader` in log-time order, each at its recorded offset from
    the first divided by `rate` after `started`; return how many."""
    count, first = 0, None
    for _schema, channel, message in reader.iter_messages(log_time_order=True):
        first = message.log_time if first is None else first
        delay = started + (message.log_time - first) / 1e9 / rate - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        pubs.put(channel, message.data)
        count += 1
    return count


@final
class _Publishers:
    """One Zenoh publisher per recorded channel, declared on `play`'s session."""

    def __init__(self, session: Any, path: str | Path, fleet: str | None,
                 key: bytes | None = None) -> None:
        self.session, self.path, self.fleet, self.key = session, path, fleet, key
        self._pubs: dict[int, Any] = {}
        self._tags: dict[int, Callable[[bytes], bytes | None]] = {}

    def __len__(self) -> int:
        return len(self._pubs)

    def declare(self, channel: Any) -> Any:
        """The publisher of `channel`: on its recorded key, or on its topic in `fleet`;
        latched topics through an advanced publisher, so late subscribers get the last."""
        import zenoh
        from zenoh import ext

        path, fleet, session = self.path, self.fleet, self.session
        if channel.message_encoding != "msgpack":
            raise ValueError(f"{path}: channel {channel.topic} is {channel.message_encoding}-"
                             "encoded (an exported copy?); play needs the msgpack recording")
        key = topic_expr(fleet, channel.topic) if fleet else channel.metadata.get("key")
        if not key:
            raise ValueError(f"{path}: channel {channel.topic} has no 'key' metadata; "
                             "give the fleet to publish into")
        if channel.metadata.get("durability") == Durability.TRANSIENT_LOCAL.value:
            pub = ext.declare_advanced_publisher(session, key, cache=ext.CacheConfig(1),
                                                 publisher_detection=True)
        else:
            pub = session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
        self._pubs[channel.id] = pub
        self._tags[channel.id] = signer(self.key, key, Role.RECORDED)
        return pub

    def put(self, channel: Any, payload: bytes) -> None:
        """Publish `payload` on `channel`'s publisher (signed as recorded, with a key)."""
        pub = self.of(channel)
        attachment = self._tags[channel.id](payload)
        if attachment is None:
            pub.put(payload)
        else:
            pub.put(payload, attachment=attachment)

    def of(self, channel: Any) -> Any:
        """The publisher of `channel`, declared on first use if the summary had no such channel."""
        return self._pubs.get(channel.id) or self.declare(channel)

    def wait_for_subscriber(self, wait_s: float) -> None:
        """Wait up to `wait_s` for some publisher to match a subscriber (the first messages
        would otherwise go nowhere)."""
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline and not any(
                getattr(p, "matching_status", None) and p.matching_status.matching
                for p in self._pubs.values()):
            time.sleep(0.02)

    def undeclare(self) -> None:
        """Undeclare every publisher."""
        for pub in self._pubs.values():
            pub.undeclare()
