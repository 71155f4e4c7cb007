"""`twinfleet foxglove`: a live fleet in Foxglove, through the official `foxglove-sdk` server.

One Zenoh session (`runtime.tools.monitor.tap.FleetTap`) hears every topic of
the fleet; each sample goes, on the loop, to a `FoxgloveBridge`, which logs it
on a Foxglove WebSocket server (``foxglove.start_server``; the Foxglove
WebSocket protocol under the subprotocol name ``foxglove.sdk.v1``, the only
name foxglove-sdk 0.30 accepts: a client offering only the older
``foxglove.websocket.v1`` is refused at the handshake) twice:

* as itself, on a channel of the same topic name, JSON-encoded with the JSON
  Schema of its type (bytes as base64: `runtime.tools.forms.json_form.message_json`),
  so the Raw Messages and Plot panels work for any node's topics;
* as Foxglove's well-known messages (`runtime.tools.forms.foxglove_scene`) of what
  the fleet's scene draws: the map as a ``foxglove.Grid``, the bodies as
  ``foxglove.SceneUpdate`` entities, scans as ``foxglove.PointCloud``,
  collisions as red markers, protobuf-encoded, all in frame ``map``, so the 3D
  panel draws the fleet with no configuration.

The scene and the latched topics (heard with history) are learned from the
fleet when its first sample arrives (`runtime.tools.view.scene_finder`); the
samples that arrive meanwhile are drawn then. A fleet without a scene gets
its JSON channels only.

A client that subscribes late gets the latest map, every robot and the last
message of each latched topic again at once (the SDK keeps no history).
Open Foxglove, "Open connection", with the printed ``ws://127.0.0.1:8765/?token=...``:
clients reach the SDK's server only through `runtime.tools.view.foxglove_gate`, which
checks their Host, Origin and token (`runtime.tools.view.web_guard`).
`twinfleet export` writes the same channels into an MCAP file.
"""

from __future__ import annotations

import asyncio
import sys
import time
from collections import deque
from collections.abc import Callable, Mapping
from typing import Any, TextIO, final

import foxglove
import msgpack

from twinfleet.runtime.contract.scene import Scene
from twinfleet.runtime.host.keys import topic_in_fleet
from twinfleet.runtime.host.schemas import message_schema
from twinfleet.runtime.tools.forms.foxglove_scene import MAP_TOPIC, ROBOTS_TOPIC, FoxgloveScene
from twinfleet.runtime.tools.forms.json_form import json_schema, message_json
from twinfleet.runtime.tools.view.foxglove_gate import FoxgloveGate, inner_certificate
from twinfleet.runtime.tools.view.web_guard import WebAccess

RESEND_DELAY_S = 0.05  # let the server finish a subscription before re-sending to it
DEFAULT_PORT = 8765  # what Foxglove's "Open connection" proposes
MAX_WAITING = 20_000  # samples kept for drawing while the scene is not known yet


@final
class FoxgloveBridge:
    """Logs fleet samples on Foxglove channels of one `foxglove.Context` (module docstring).

    Args:
        context: the SDK context the WebSocket server (or an MCAP writer) sinks.
        fleet: the fleet to show; ``*`` takes the first fleet whose data arrives.
        latched: fully qualified names of transient-local topics (re-sent to late clients).
        scene: how the fleet is drawn, if known now (else `set_scene` says it later).
    """

    def __init__(self, context: foxglove.Context, fleet: str = "*",
                 latched: tuple[str, ...] = (), scene: Scene | None = None) -> None:
        self.context, self.fleet, self.latched = context, fleet, latched
        self.view = FoxgloveScene(scene) if scene is not None else None
        self.known_schemas: dict[str, dict[str, Any]] = {}
        self.channels: dict[str, foxglove.Channel] = {}
        self.last: dict[str, bytes] = {}  # every topic's last JSON copy (latched ones re-sent)
        self.logged: dict[str, int] = {}
        self._waiting: list[tuple[str, bytes]] | None = []  # until the schemas are known
        # until the scene is known: what to draw then
        self._undrawn: deque[tuple[str, Mapping[str, Any], int]] | None = (
            None if scene is not None else deque(maxlen=MAX_WAITING))

    def start(self, schemas: Mapping[str, dict[str, Any]]) -> None:
        """Take the data schemas the fleet's nodes serve, then log what waited for them."""
        self.known_schemas.update(schemas)
        waiting, self._waiting = self._waiting or [], None
        for key, payload in waiting:
            self.on_sample(key, payload)

    def set_scene(self, scene: Scene | None, latched: tuple[str, ...] = ()) -> None:
        """Draw with `scene` from now on (None: draw nothing), and draw what waited for it;
        `latched` adds to the topics re-sent to late clients."""
        self.latched = (*self.latched, *(t for t in latched if t not in self.latched))
        self.view = FoxgloveScene(scene) if scene is not None else None
        undrawn, self._undrawn = self._undrawn or (), None
        for topic, env, when in undrawn:
            self._draw(topic, env, when)

    def on_sample(self, key: str, payload: bytes) -> None:
        """One raw sample of key ``twinfleet/<fleet>/<topic>`` (call on the loop); samples
        wait until `start` so that every channel gets its exact schema."""
        if self._waiting is not None:
            self._waiting.append((key, payload))
            return
        where = topic_in_fleet(self.fleet, key)
        if where is None:
            return
        # '*' locks onto the first fleet whose data arrives
        self.fleet, topic = where.fleet, where.topic
        try:
            env = msgpack.unpackb(payload, raw=False, strict_map_key=False)
        except Exception:  # msgpack raises several unrelated types
            return
        if not isinstance(env, dict) or not isinstance(env.get("type"), str):
            return
        now = time.time_ns()
        copy = message_json(payload)
        self._json_channel(topic, env).log(copy, log_time=now)
        self._count(topic)
        self.last[topic] = copy
        if self._undrawn is not None:
            self._undrawn.append((topic, env, now))
        else:
            self._draw(topic, env, now)

    def _draw(self, topic: str, env: Mapping[str, Any], now: int) -> None:
        """Log the Foxglove messages that the scene draws of one envelope."""
        for fox_topic, msg in self.view.feed(topic, env, now) if self.view is not None else ():
            self._typed_channel(fox_topic, msg).log(msg.encode(), log_time=now)
            self._count(fox_topic)

    def _count(self, topic: str) -> None:
        self.logged[topic] = self.logged.get(topic, 0) + 1

    def _json_channel(self, topic: str, env: Mapping[str, Any]) -> foxglove.Channel:
        channel = self.channels.get(topic)
        if channel is None:
            schema = json_schema(message_schema(env["type"], env.get("data"), self.known_schemas))
            channel = foxglove.Channel(topic, schema=schema, context=self.context,
                                       metadata={"twinfleet_type": env["type"]})
            self.channels[topic] = channel
        return channel

    def _typed_channel(self, topic: str, msg: Any) -> foxglove.Channel:
        channel = self.channels.get(topic)
        if channel is None:
            channel = foxglove.Channel(topic, schema=type(msg).get_schema(),
                                       message_encoding="protobuf", context=self.context)
            self.channels[topic] = channel
        return channel

    def resend(self, topic: str) -> None:
        """Log again what a late subscriber of `topic` needs: the map, the robots, a latched
        topic's last message."""
        now, view = time.time_ns(), self.view
        if topic == MAP_TOPIC and view is not None and view.grid is not None:
            self.channels[topic].log(view.grid.encode(), log_time=now)
        elif topic == ROBOTS_TOPIC and view is not None and view.poses:
            from foxglove.messages import SceneUpdate

            entities = [view._entity(r, now) for r in view.order if r in view.poses]  # noqa: SLF001
            self.channels[topic].log(SceneUpdate(entities=entities).encode(), log_time=now)
        elif topic in self.last and topic in self.latched:
            self.channels[topic].log(self.last[topic], log_time=now)


class _Listener(foxglove.ServerListener):
    """The server's subscribe callback hands a re-send to the loop (SDK threads never touch
    the bridge)."""

    def __init__(self, loop: asyncio.AbstractEventLoop, bridge: FoxgloveBridge) -> None:
        self.loop, self.bridge = loop, bridge

    def on_subscribe(self, _client: Any, channel: Any) -> None:
        topic = channel.topic
        self.loop.call_soon_threadsafe(self.loop.call_later, RESEND_DELAY_S,
                                       self.bridge.resend, topic)


async def serve_foxglove(endpoint: str, fleet: str, *, port: int | None = None,
                         out: TextIO = sys.stdout, ready: Callable[[int], None] | None = None,
                         stop: asyncio.Event | None = None, auth: Any = None,
                         web: WebAccess | None = None) -> None:
    """Bridge the fleet behind `endpoint` to Foxglove on 127.0.0.1:`port` until `stop` is set
    (None: 8765, or a free port if that one is taken; 0: a free port; `ready` gets the port).
    `auth`: the fleet's credentials (default: this machine's registry); `web`: who may
    connect (default: a fresh token, the local host names)."""
    from twinfleet.runtime.tools.monitor.graph import fleet_schemas
    from twinfleet.runtime.tools.monitor.tap import FleetTap, tap_config
    from twinfleet.runtime.tools.view.scene_finder import SceneFinder

    context = foxglove.Context()
    bridge = FoxgloveBridge(context, fleet)
    listener = _Listener(asyncio.get_running_loop(), bridge)
    access = web or WebAccess()
    tls, client_tls = inner_certificate()
    server = foxglove.start_server(name=f"twinfleet {fleet}", host="127.0.0.1", port=0,
                                   context=context, server_listener=listener,
                                   tls_cert=tls.certificate, tls_key=tls.key)
    gate = FoxgloveGate(server.port, client_tls, access,
                        lambda text: print(f"[foxglove] {text}", file=out, flush=True))
    try:
        await _open_gate(gate, port)
    except OSError:
        server.stop()
        raise

    def deliver(key: str, payload: bytes) -> None:
        finder.seen(key)
        bridge.on_sample(key, payload)

    tap = FleetTap(lambda: tap_config(endpoint, auth), fleet, deliver, retry=True)
    finder = SceneFinder(tap, lambda scene: bridge.set_scene(scene, tap.latched), out=out)
    try:
        opening = asyncio.ensure_future(tap.open())
        print(f"[foxglove] fleet {fleet!r} via {endpoint}: in Foxglove, open connection "
              f"{access.url('ws', gate.port)}", file=out, flush=True)
        if ready is not None:
            ready(gate.port)
        stopping = asyncio.ensure_future((stop or asyncio.Event()).wait())
        await asyncio.wait([opening, stopping], return_when=asyncio.FIRST_COMPLETED)
        if opening.done() and tap.session is not None:
            bridge.start(await asyncio.to_thread(fleet_schemas, tap.session, fleet))
            await stopping
    finally:
        tap.stop()
        await finder.close()
        await tap.close()
        await gate.stop()
        server.stop()


async def _open_gate(gate: FoxgloveGate, port: int | None) -> None:
    """Listen on `port`; None: Foxglove's usual port, or any free one when it is taken (by
    `twinfleet view`?)."""
    try:
        await gate.start(DEFAULT_PORT if port is None else port)
    except OSError:
        if port is not None:
            raise
        await gate.start(0)


def run_foxglove(endpoint: str, fleet: str, *, port: int | None = None, auth: Any = None,
                 web: WebAccess | None = None) -> int:
    """Blocking entry point of `twinfleet foxglove`: serve until SIGINT/SIGTERM."""
    import signal

    async def main() -> None:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        await serve_foxglove(endpoint, fleet, port=port, stop=stop, auth=auth, web=web)

    asyncio.run(main())
    return 0
